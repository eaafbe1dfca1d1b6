#!/usr/bin/env bash
# What splitting a render costs: renders the same image on one machine and as
# N parts (run one after another here, each with the same thread count, as N
# array tasks would run side by side), checks that the merge is byte-identical,
# and prints a table: wall and CPU seconds (user + system, from the shell's
# `time`, so process start, scene load, BVH build and partial writing count),
# the CPU overhead of the split against the one-machine render, partial sizes
# and merge time.
#
#   scripts/measure-split.sh [-n "2 8"] [-t THREADS] [-- RENDER ARGS]
# default render: scenes/cs184/sky/CBbunny.dae -r 480 360 -s 256 -m 5
set -euo pipefail
cd "$(dirname "$0")/.."
ns="8"; threads="$(nproc)"
while (($#)); do
    case "$1" in
        -n) ns="$2"; shift 2 ;;
        -t) threads="$2"; shift 2 ;;
        --) shift; break ;;
        *) echo "measure-split: unknown option $1" >&2; exit 2 ;;
    esac
done
args=("$@")
if ((${#args[@]} == 0)); then
    scenes=scenes/cs184
    args=("$scenes/sky/CBbunny.dae" -r 480 360 -s 256 -m 5)
fi
cargo build --release --quiet
pt="$PWD/target/release/pathtracer"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# Runs "$@" and sets wall/cpu (seconds) from bash's time.
measure() {
    local t
    t="$( { TIMEFORMAT='%R %U %S'; time "$@" >/dev/null; } 2>&1 | tail -1)"
    read -r wall user sys <<<"$t"
    cpu="$(awk -v u="$user" -v s="$sys" 'BEGIN { print u + s }')"
}

cpu_model="$(lscpu | sed -n 's/^Model name: *//p' | head -1)"
echo "CPU: $cpu_model ($(nproc) cores); render: ${args[*]} -t $threads"
measure "$pt" "${args[@]}" -t "$threads" -f "$work/one.png" --exr "$work/one.exr" --variance-exr "$work/onev.exr"
one_wall="$wall"; one_cpu="$cpu"
printf '%-24s %9s %9s %12s %14s %10s %9s\n' "run" "wall s" "CPU s" "CPU / 1 run" "partials MB" "merge s" "identical"
printf '%-24s %9.2f %9.2f %12s %14s %10s %9s\n' "one machine" "$one_wall" "$one_cpu" "1.000" "-" "-" "-"
for n in $ns; do
    mkdir -p "$work/n$n"
    total_wall=0; total_cpu=0
    for ((i = 0; i < n; i++)); do
        measure "$pt" "${args[@]}" -t "$threads" --part "$i/$n" --partial "$work/n$n/part-$i.ptp"
        total_wall="$(awk -v a="$total_wall" -v b="$wall" 'BEGIN { print a + b }')"
        total_cpu="$(awk -v a="$total_cpu" -v b="$cpu" 'BEGIN { print a + b }')"
    done
    size="$(du -cb "$work/n$n"/part-*.ptp | tail -1 | cut -f1)"
    measure "$pt" merge "$work/n$n"/part-*.ptp -f "$work/n$n/one.png" --exr "$work/n$n/one.exr" --variance-exr "$work/n$n/onev.exr"
    same=yes
    for f in one.png one_rate.png one.exr onev.exr; do
        [[ ! -e "$work/$f" && ! -e "$work/n$n/$f" ]] || cmp -s "$work/$f" "$work/n$n/$f" || same=NO
    done
    printf '%-24s %9.2f %9.2f %12.3f %14.1f %10.2f %9s\n' "N=$n split (summed)" "$total_wall" "$total_cpu" \
        "$(awk -v a="$total_cpu" -v b="$one_cpu" 'BEGIN { print a / b }')" "$(awk -v a="$size" 'BEGIN { print a / 1e6 }')" "$wall" "$same"
    [[ "$same" == yes ]] || { echo "measure-split: the merged images differ from the one-machine render" >&2; exit 1; }
done
