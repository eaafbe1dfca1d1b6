#!/usr/bin/env bash
# Thread scaling: `pathtracer bench --threads 1,2,4,8,16` per scene (native and
# Embree, plus the peers built in unless BENCH_ARGS says --no-peers), then, with RENDERS=1,
# CBbunny and CBspheres path-traced at 480x360, 32 spp, -m 5 at each thread count per backend,
# with each image's md5 (the same seed must give the same image at any thread count). One bench
# process per scene, each appending to the output as it finishes, so a run cut short (a
# machine's time limit) keeps what it measured: the scenes go cheapest first.
#
#   scripts/measure-scaling.sh [OUT_DIR] [THREADS]     # defaults: target/scaling (not committed), 1,2,4,8,16
#
# Environment:
#   PT=path/to/pathtracer  a binary built elsewhere (for a machine without Rust:
#                          a --features peers build carried there with libembree3 and libtbb);
#                          otherwise this builds one with --features peers
#   SCENES="cow CBbunny grass:2M@262144 ..."  bench scenes in order; NAME@N times N rays
#                          for that scene instead of the bench's 2^20 (grass's shadow rays run
#                          at 0.3 Mrays/s on one thread)
#   BENCH_ARGS="--passes 3 --throughput-only"  more `pathtracer bench` options
#   RENDERS=1              also time the renders
# Scene names are looked up as `bench` does ($PATHTRACER_SCENES, ./scenes, scenes/cs184).
set -uo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/scaling}
threads=${2:-1,2,4,8,16}
scenes=${SCENES:-cow CBbunny maxplanck beetle arch:2M stadium:2M subdiv:bunny:1.5M sphere:1M arch:10M sphere:5M grass:2M}
if [ -z "${PT:-}" ]; then
    cargo build --release -q --features peers || exit 1
    PT=./target/release/pathtracer
fi
mkdir -p "$out"
{ lscpu; nproc; } > "$out/machine.txt" 2>&1
echo "scene,rays,threads,backend,mrays_per_s" > "$out/bench.csv"
: > "$out/bench.md"
start=$SECONDS
for entry in $scenes; do
    s=${entry%@*}
    rays=()
    [ "$s" != "$entry" ] && rays=(--rays "${entry#*@}")
    tmp=$(mktemp)
    # shellcheck disable=SC2086 # BENCH_ARGS is a list of options
    "$PT" bench "$s" --threads "$threads" --no-render --backends native,embree "${rays[@]}" --csv "$tmp" ${BENCH_ARGS:-} >> "$out/bench.md"
    echo "bench $entry rc=$? t=$((SECONDS - start)) s"
    tail -n +2 "$tmp" >> "$out/bench.csv"
    rm -f "$tmp"
done
[ "${RENDERS:-0}" = 1 ] || exit 0
: > "$out/render.txt"
find_scene() {
    for d in "${PATHTRACER_SCENES:-}" scenes scenes/cs184/*; do
        [ -n "$d" ] && [ -f "$d/$1.dae" ] && { echo "$d/$1.dae"; return; }
    done
    echo "measure-scaling: $1.dae not found" >&2
}
img=$(mktemp -d)
for sc in CBbunny CBspheres; do
    file=$(find_scene $sc)
    [ -z "$file" ] && continue
    for b in native embree; do
        for t in ${threads//,/ }; do
            line=$("$PT" "$file" -t "$t" -s 32 -m 5 -r 480 360 --backend $b -f "$img/r.png" 2>&1 | tail -1)
            echo "render $sc $b t=$t | $(echo "$line" | grep -o 'render [0-9.]* s | [0-9]* rays | [0-9.]* Mrays/s') | md5 $(md5sum < "$img/r.png" | cut -c1-8)" | tee -a "$out/render.txt"
        done
    done
done
rm -rf "$img"
