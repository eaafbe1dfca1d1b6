#!/usr/bin/env bash
# Error against time for the sampling techniques (the protocol of docs/benchmarks/sampling-techniques.md): for
# each scene, a high-spp reference, then every combination of the axes that
# scene exercises — sampler (independent | sobol) x light sampling (area |
# solid-angle: rectangles and spheres) x sky sampling (uniform | lune: the
# hemisphere light at diffuse vertices) x environment sampling (map | cosine:
# the map times the receiver's cosine bound | product: that, and inside the
# lobe at glossy vertices) x the specular guide (0 | 0.2: the
# share of diffuse bounces aimed at mirror, glass and metal objects) — at 4,
# 16, 64, 256 spp over several
# seeds. Prints relMSE (mean over seeds), the log-log slope of relMSE against
# spp, render seconds (median over seeds, from the summary line: process
# start and scene load excluded), efficiency 1/(relMSE * seconds), and the
# gain of each row over the CS184 row (independent, area, uniform, guide 0)
# at the same spp, in relMSE and in efficiency (CS184's row; for env, its map
# row).
#
#   scripts/measure-sampling.sh [-r "W H"] [-n SEEDS] [-R REF_SPP] [-s "SPPS"] [SCENE_KEY...]
# scene keys: m1 (built-in scene, direct light), m5 (built-in, -m 5),
#             bunny (sky/bunny.dae -m 5: the hemisphere light),
#             env (sky/bunny_unlit.dae -e studio.exr -m 5),
#             glossy_env (sky/bunny_microfacet_cu_unlit.dae -e courtyard.exr -m 3:
#             the copper bunny, where `product` samples inside the glossy lobe
#             and `cosine` by the cosine bound; not run by default),
#             spheres (sky/CBspheres.dae -m 5: mirror and glass spheres)
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
((${#keys[@]})) || keys=(m1 m5 bunny env spheres)
shared=scenes/cs184
envmaps=scenes/envmaps
cargo build --release --quiet
pt="$PWD/target/release/pathtracer"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

need() {
    [[ -e "$1" ]] || { echo "measure-sampling: $1 not found (scenes/cs184 and scenes/envmaps in the repository)" >&2; exit 1; }
}
args_of() {
    case "$1" in
        m1) echo "-m 1" ;;
        m5) echo "-m 5" ;;
        bunny) need "$shared/sky/bunny.dae"; echo "$shared/sky/bunny.dae -m 5" ;;
        env) need "$shared/sky/bunny_unlit.dae"; need "$envmaps/studio.exr"; echo "$shared/sky/bunny_unlit.dae -e $envmaps/studio.exr -m 5" ;;
        glossy_env) need "$shared/sky/bunny_microfacet_cu_unlit.dae"; need "$envmaps/courtyard.exr"; echo "$shared/sky/bunny_microfacet_cu_unlit.dae -e $envmaps/courtyard.exr -m 3" ;;
        spheres) need "$shared/sky/CBspheres.dae"; echo "$shared/sky/CBspheres.dae -m 5" ;;
        *) echo "measure-sampling: unknown scene key $1" >&2; exit 2 ;;
    esac
}
# The axes a scene exercises: combinations as "sampler,light,sky,env,guide"
# (the guide changes nothing where no mirror, glass or metal object is).
combos_of() {
    case "$1" in
        m1 | m5) echo "independent,area,uniform,map,0 sobol,area,uniform,map,0.2 independent,solid-angle,uniform,map,0.2 sobol,solid-angle,uniform,map,0.2" ;;
        bunny) echo "independent,area,uniform,map,0 sobol,area,uniform,map,0.2 independent,area,lune,map,0.2 sobol,area,lune,map,0.2" ;;
        env) echo "independent,area,uniform,map,0 sobol,area,uniform,map,0.2 independent,area,uniform,product,0.2 sobol,area,uniform,product,0.2" ;;
        glossy_env) echo "independent,area,uniform,map,0 sobol,area,uniform,map,0.2 sobol,area,uniform,cosine,0.2 sobol,area,uniform,product,0.2" ;;
        spheres) echo "independent,area,uniform,map,0 sobol,solid-angle,uniform,map,0 sobol,solid-angle,uniform,map,0.2" ;;
    esac
}

echo "CPU: $(lscpu | sed -n 's/^Model name: *//p' | head -1) ($(nproc) cores); -r $res --keep-fov; $seeds seeds; reference $ref_spp spp (sobol, solid-angle, lune, product, guide 0.2)"
printf '%-7s %-12s %-12s %-8s %-8s %-5s %5s %11s %7s %9s %11s %9s %9s\n' scene sampler light sky env guide spp relMSE slope seconds efficiency "gain" "eff.gain"
for key in "${keys[@]}"; do
    read -r -a a <<<"$(args_of "$key")"
    ref="$work/$key-ref.exr"
    "$pt" "${a[@]}" -r $res --keep-fov -s "$ref_spp" --seed 99991 --exr "$ref" -f "$work/ref.png" >/dev/null
    declare -A err=() eff=()
    for combo in $(combos_of "$key"); do
        IFS=, read -r sampler light sky envs guide <<<"$combo"
        prev=""
        for spp in $spps; do
            total=0; times=()
            for ((s = 0; s < seeds; s++)); do
                out="$("$pt" "${a[@]}" -r $res --keep-fov -s "$spp" --sampler "$sampler" --light-sampling "$light" --sky-sampling "$sky" --env-sampling "$envs" --specular-guide "$guide" --seed "$s" --exr "$work/x.exr" -f "$work/x.png")"
                times+=("$(sed -n 's/.*| render \([0-9.]*\) s |.*/\1/p' <<<"$out")")
                e="$("$pt" compare "$ref" "$work/x.exr" | sed -n 's/.*relMSE \([0-9.e+-]*\) .*/\1/p')"
                total="$(awk -v a="$total" -v b="$e" 'BEGIN { print a + b }')"
            done
            mse="$(awk -v a="$total" -v n="$seeds" 'BEGIN { printf "%.3e", a / n }')"
            sec="$(printf '%s\n' "${times[@]}" | sort -g | awk '{ v[NR] = $1 } END { printf "%.4f", (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }')"
            slope="-"
            [[ -n "$prev" ]] && slope="$(awk -v a="$prev" -v b="$mse" 'BEGIN { printf "%.2f", log(b / a) / log(4) }')"
            prev="$mse"
            e_now="$(awk -v m="$mse" -v t="$sec" 'BEGIN { printf "%.4g", 1 / (m * t) }')"
            if [[ "$combo" == "independent,area,uniform,map,0" ]]; then
                err[$spp]="$mse"; eff[$spp]="$e_now"
            fi
            gain="$(awk -v a="${err[$spp]}" -v b="$mse" 'BEGIN { printf "%.2fx", a / b }')"
            egain="$(awk -v a="${eff[$spp]}" -v b="$e_now" 'BEGIN { printf "%.2fx", b / a }')"
            printf '%-7s %-12s %-12s %-8s %-8s %-5s %5s %11s %7s %9s %11s %9s %9s\n' "$key" "$sampler" "$light" "$sky" "$envs" "$guide" "$spp" "$mse" "$slope" "$sec" "$e_now" "$gain" "$egain"
        done
    done
    unset err eff
done
