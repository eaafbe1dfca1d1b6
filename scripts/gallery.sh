#!/usr/bin/env bash
# Regenerates the gallery (docs/gallery.md, docs/gallery/): CS184's figures from our CLI.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q
pt=target/release/pathtracer
g=docs/gallery
mkdir -p "$g"
bunny=${SCENES:-scenes/cs184}/sky/CBbunny.dae
size=(-r 200 150 --keep-fov --seed 1)
for m in 0 1 2 3 4 5; do
    "$pt" "$bunny" "${size[@]}" -s 256 -m $m -f "$g/bunny_m${m}.png" > /dev/null
    "$pt" "$bunny" "${size[@]}" -s 256 -m $m -o 0 -f "$g/bunny_m${m}_o0.png" > /dev/null
done
"$pt" "$bunny" "${size[@]}" -s 256 -m 100 -f "$g/bunny_m100_rr.png" > /dev/null
for s in 1 4 16 64 256 1024; do
    "$pt" "${size[@]}" -s $s -m 5 -f "$g/spheres_s${s}.png" > /dev/null
done
for l in 1 4 16 64; do
    "$pt" "${size[@]}" -s 1 -l $l -m 1 -f "$g/spheres_l${l}.png" > /dev/null
done
"$pt" "$bunny" "${size[@]}" -s 1024 -a 64 0.05 -m 5 -f "$g/bunny_adaptive.png" > /dev/null
# Every shipped scene at -m 5 (256 spp). Scenes with no light of their own (the meshedit
# and simple scenes, the _unlit ones) are lit by the courtyard environment map (-e).
envs=${ENVMAPS:-scenes/envmaps}
mkdir -p "$g/scenes"
for f in ${SCENES:-scenes/cs184}/*/*.dae; do
    name=$(basename "$f" .dae)
    probe=$("$pt" "$f" -r 8 8 -s 1 -m 0 -f /tmp/gallery-probe.png)
    if grep -q "has no light" <<< "$probe"; then
        "$pt" "$f" "${size[@]}" -s 256 -m 5 -e "$envs/courtyard.exr" -f "$g/scenes/$name.png" > /dev/null
    else
        "$pt" "$f" "${size[@]}" -s 256 -m 5 -f "$g/scenes/$name.png" > /dev/null
    fi
done
rm -f /tmp/gallery-probe.png /tmp/gallery-probe_rate.png
# Environment light with depth of field: the copper bunny in the studio, focused on the bunny (3.3 from the camera).
"$pt" ${SCENES:-scenes/cs184}/sky/bunny_microfacet_cu_unlit.dae -r 400 300 --keep-fov --seed 1 -s 512 -m 8 \
    -e "$envs/studio.exr" -b 0.06 -d 3.3 -f "$g/env_dof.png" > /dev/null
rm -f "$g"/*_rate.png.tmp
# Keep only the rate image of the adaptive render.
find "$g" -name '*_rate.png' ! -name 'bunny_adaptive_rate.png' -delete
ls "$g/scenes"
ls "$g"
