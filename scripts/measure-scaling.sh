#!/usr/bin/env bash
# Thread scaling (issue 14): `pathtracer bench --threads 1,2,4,...` on every default bench
# scene (native, Embree and the peers built in), then CBbunny and CBspheres path-traced at
# 480x360, 32 spp, -m 5 at each thread count per backend, with each image's md5 (the same
# seed must give the same image at any thread count). One bench process per scene, each
# appending to the output as it finishes, so a run cut short keeps what it measured.
#
#   scripts/measure-scaling.sh [OUT_DIR] [THREADS]     # defaults: docs/scaling, 1,2,4,8,16
#
# PT=path/to/pathtracer uses a binary built elsewhere (the 16-core run in the README was made
# that way: a --features peers build carried to the lent machine with libembree3 and libtbb);
# otherwise this builds one with --features peers. Scene names are looked up as `bench` does
# ($PATHTRACER_SCENES, ./scenes, ../shared/scenes/cs184).
set -uo pipefail
cd "$(dirname "$0")/.."
out=${1:-docs/scaling}
threads=${2:-1,2,4,8,16}
if [ -z "${PT:-}" ]; then
    cargo build --release -q --features peers || exit 1
    PT=./target/release/pathtracer
fi
mkdir -p "$out"
{ lscpu; nproc; } > "$out/machine.txt" 2>&1
echo "scene,rays,threads,backend,mrays_per_s" > "$out/bench.csv"
: > "$out/bench.md"
: > "$out/render.txt"
start=$SECONDS
bench() {
    for s in "$@"; do
        tmp=$(mktemp)
        "$PT" bench "$s" --threads "$threads" --no-render --backends native,embree --csv "$tmp" >> "$out/bench.md"
        echo "bench $s rc=$? t=$((SECONDS - start)) s"
        tail -n +2 "$tmp" >> "$out/bench.csv"
        rm -f "$tmp"
    done
}
bench cow CBbunny maxplanck beetle arch:2M grass:2M stadium:2M subdiv:bunny:1.5M
find_scene() {
    for d in "${PATHTRACER_SCENES:-}" scenes ../shared/scenes/cs184/*; do
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
bench sphere:1M sphere:5M arch:10M
