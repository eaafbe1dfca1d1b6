#!/usr/bin/env bash
# Error against time for the samplers (issue 13's protocol, the sampler axis
# so far): for each scene, a high-spp reference, then every sampler at
# 4, 16, 64, 256 spp over several seeds; prints relMSE (mean over seeds),
# the log-log slope of relMSE against spp, render seconds (from the summary
# line: process start and scene load excluded) and efficiency
# 1/(relMSE * seconds), plus the Sobol / independent relMSE ratio.
#
#   scripts/measure-sampling.sh [-r "W H"] [-n SEEDS] [-R REF_SPP] [SCENE_KEY...]
# scene keys: m1 (built-in scene, direct light), m5 (built-in, -m 5),
#             bunny (sky/bunny.dae), env (sky/bunny_unlit.dae -e studio.exr)
set -euo pipefail
cd "$(dirname "$0")/.."
res="160 120"; seeds=8; ref_spp=8192; spps="4 16 64 256"
while (($#)); do
    case "$1" in
        -r) res="$2"; shift 2 ;;
        -n) seeds="$2"; shift 2 ;;
        -R) ref_spp="$2"; shift 2 ;;
        -s) spps="$2"; shift 2 ;;
        *) break ;;
    esac
done
keys=("$@")
((${#keys[@]})) || keys=(m1 m5 bunny env)
shared="${PATHTRACER_SHARED_SCENES:-../shared/scenes/cs184}"
envmaps="$(dirname "$shared")/../envmaps"
cargo build --release --quiet
pt="$PWD/target/release/pathtracer"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

args_of() {
    case "$1" in
        m1) echo "-m 1" ;;
        m5) echo "-m 5" ;;
        bunny) echo "$shared/sky/bunny.dae -m 5" ;;
        env) echo "$shared/sky/bunny_unlit.dae -e $envmaps/studio.exr -m 5" ;;
        *) echo "measure-sampling: unknown scene key $1" >&2; exit 2 ;;
    esac
}

echo "CPU: $(lscpu | sed -n 's/^Model name: *//p' | head -1) ($(nproc) cores); -r $res --keep-fov; $seeds seeds; reference $ref_spp spp (sobol)"
printf '%-6s %-12s %5s %12s %8s %9s %12s %10s\n' scene sampler spp relMSE slope seconds efficiency "ind/sobol"
for key in "${keys[@]}"; do
    read -r -a a <<<"$(args_of "$key")"
    ref="$work/$key-ref.exr"
    "$pt" "${a[@]}" -r $res --keep-fov -s "$ref_spp" --seed 99991 --exr "$ref" -f "$work/ref.png" >/dev/null
    declare -A err=()
    for sampler in independent sobol; do
        prev=""
        for spp in $spps; do
            total=0; secs=0
            for ((s = 0; s < seeds; s++)); do
                out="$("$pt" "${a[@]}" -r $res --keep-fov -s "$spp" --sampler "$sampler" --seed "$s" --exr "$work/x.exr" -f "$work/x.png")"
                t="$(sed -n 's/.*| render \([0-9.]*\) s |.*/\1/p' <<<"$out")"
                e="$("$pt" compare "$ref" "$work/x.exr" | sed -n 's/.*relMSE \([0-9.e+-]*\) .*/\1/p')"
                total="$(awk -v a="$total" -v b="$e" 'BEGIN { print a + b }')"
                secs="$(awk -v a="$secs" -v b="$t" 'BEGIN { print a + b }')"
            done
            mse="$(awk -v a="$total" -v n="$seeds" 'BEGIN { printf "%.4e", a / n }')"
            sec="$(awk -v a="$secs" -v n="$seeds" 'BEGIN { printf "%.3f", a / n }')"
            slope="-"
            [[ -n "$prev" ]] && slope="$(awk -v a="$prev" -v b="$mse" 'BEGIN { printf "%.2f", log(b / a) / log(4) }')"
            prev="$mse"
            err[$sampler-$spp]="$mse"
            ratio="-"
            [[ "$sampler" == sobol ]] && ratio="$(awk -v a="${err[independent-$spp]}" -v b="$mse" 'BEGIN { printf "%.2f", a / b }')"
            eff="$(awk -v m="$mse" -v t="$sec" 'BEGIN { printf "%.4g", 1 / (m * t) }')"
            printf '%-6s %-12s %5s %12s %8s %9s %12s %10s\n' "$key" "$sampler" "$spp" "$mse" "$slope" "$sec" "$eff" "$ratio"
        done
    done
    unset err
done
