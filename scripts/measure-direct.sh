#!/usr/bin/env bash
# Direct lighting on CBspheres_lambertian at 256x192 (-m 1): render time and
# relMSE against a 16x longer light-sampling render, for light sampling,
# hemisphere sampling and adaptive sampling, at equal samples and equal time.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q
pt=target/release/pathtracer
out=${1:-target/measure-direct}
mkdir -p "$out"
common=(-r 256 192 -m 1)
run() { # name, args...
    local name=$1; shift
    local t0=$(date +%s.%N)
    "$pt" "${common[@]}" "$@" -f "$out/$name.png" --exr "$out/$name.exr" > "$out/$name.log"
    local t1=$(date +%s.%N)
    printf '%s %.3f\n' "$name" "$(echo "$t1 - $t0" | bc)" >> "$out/times.txt"
}
rm -f "$out/times.txt"
run reference -s 1024 --seed 99
run light64 -s 64 --seed 1
run hemi64 -s 64 -H --seed 1
run adaptive64 -s 64 -a 16 0.05 --seed 1
run adaptive64_pilot -s 64 -a 16 0.05 --adaptive-pilot --seed 1
# Equal time: hemisphere and adaptive with the sample counts that take as long
# as light sampling at 64 spp (scaled from the runs above).
tl=$(awk '$1=="light64"{print $2}' "$out/times.txt")
th=$(awk '$1=="hemi64"{print $2}' "$out/times.txt")
ns=$(echo "64 * $tl / $th" | bc -l | awk '{n=int($1+0.5); if (n<1) n=1; print n}')
run hemi_equal_time -s "$ns" -H --seed 1
cat "$out/times.txt"
"$pt" compare "$out/reference.exr" "$out"/light64.exr "$out"/hemi64.exr "$out"/adaptive64.exr "$out"/adaptive64_pilot.exr "$out"/hemi_equal_time.exr
grep -h "render" "$out"/*.log | sed 's/|.*backend/| backend/' | cut -c1-200
