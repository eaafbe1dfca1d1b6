#!/usr/bin/env bash
# Bias of CS184's adaptive stopping rule against the pilot-sample variant:
# K independent adaptive renders per mode, each compared with a long uniform
# reference; the mean relative bias over the K runs and its standard error.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q
pt=target/release/pathtracer
out=${OUT:-target/measure-adaptive}
k=${K:-16}
mkdir -p "$out"
scene=${SCENE:-}
view=(-r 100 75 --keep-fov -m 5)
"$pt" $scene "${view[@]}" -s 8192 --seed 1000 -f "$out/ref.png" --exr "$out/ref.exr" > /dev/null
for mode in cs184 pilot; do
    extra=(); [ "$mode" = pilot ] && extra=(--adaptive-pilot)
    : > "$out/$mode.txt"; : > "$out/$mode.rays"
    for seed in $(seq 1 "$k"); do
        "$pt" $scene "${view[@]}" -s 512 -a 32 0.05 "${extra[@]}" --seed "$seed" -f "$out/$mode$seed.png" --exr "$out/$mode$seed.exr" \
            | grep -o '[0-9]* rays' >> "$out/$mode.rays"
        "$pt" compare "$out/ref.exr" "$out/$mode$seed.exr" | sed 's/.*relative bias //; s/%//' >> "$out/$mode.txt"
    done
    awk -v m="$mode" '{s+=$1; ss+=$1*$1; n++} END {mu=s/n; se=sqrt((ss/n-mu*mu)/(n-1)); printf "%s: mean relative bias %+.3f%% +- %.3f%% (%d runs)\n", m, mu, se, n}' "$out/$mode.txt"
    awk -v m="$mode" '{s+=$1; n++} END {printf "%s: %.1f Mrays per render\n", m, s/n/1e6}' "$out/$mode.rays"
done
