#!/usr/bin/env bash
# Checks that two builds render the same bytes: every shipped scene (scenes/cs184, the
# environment-lit ones also under studio.exr) with every integrator and mode — the path
# tracer, BDPT with each light-path mode, light tracing, normals, depth, object ids — at a
# small size, each image's linear OpenEXR compared byte for byte. For refactors that must not
# change an image: build the commit before into another target folder and compare.
#
#   scripts/same-images.sh OLD_PATHTRACER NEW_PATHTRACER [-s SPP] [-r W H]
#
# Example (the commit before against the working tree):
#   git worktree add /tmp/before HEAD~1 && (cd /tmp/before && cargo build --release)
#   cargo build --release && scripts/same-images.sh /tmp/before/target/release/pathtracer target/release/pathtracer
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 2 ] || { echo "usage: scripts/same-images.sh OLD_PATHTRACER NEW_PATHTRACER [-s SPP] [-r W H]" >&2; exit 2; }
old=$(realpath "$1"); new=$(realpath "$2"); shift 2
size=(-r 48 36 --keep-fov); spp=(-s 4)
while [ $# -gt 0 ]; do
    case "$1" in
        -s) spp=(-s "$2"); shift 2 ;;
        -r) size=(-r "$2" "$3" --keep-fov); shift 3 ;;
        *) echo "same-images: unknown option $1" >&2; exit 2 ;;
    esac
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
modes=(
    "path|--integrator path -m 5"
    "bdpt_all|--integrator bdpt --bdpt-light-paths all -m 5"
    "bdpt_specular|--integrator bdpt --bdpt-light-paths specular -m 5"
    "light|--integrator light -m 5"
    "normals|--integrator normals"
    "depth|--integrator depth"
    "object_id|--integrator object-id"
)
compared=0; differ=0; refused=0
for scene in scenes/cs184/*/*.dae; do
    name=$(basename "$scene" .dae)
    extras=("")
    case "$name" in *unlit*) extras=("-e scenes/envmaps/studio.exr") ;; esac
    for mode in "${modes[@]}"; do
        tag=${mode%%|*}; flags=${mode#*|}
        for extra in "${extras[@]}"; do
            case "$tag" in normals|depth|object_id) [ -n "$extra" ] && continue ;; esac
            out_old="$work/$name.$tag.old.exr"; out_new="$work/$name.$tag.new.exr"
            # shellcheck disable=SC2086
            a=0; "$old" "$scene" $flags $extra "${size[@]}" "${spp[@]}" -t 2 --seed 3 -f "$work/o.png" --exr "$out_old" >/dev/null 2>"$work/old.err" || a=$?
            b=0; "$new" "$scene" $flags $extra "${size[@]}" "${spp[@]}" -t 2 --seed 3 -f "$work/n.png" --exr "$out_new" >/dev/null 2>"$work/new.err" || b=$?
            if [ "$a" -ne 0 ] || [ "$b" -ne 0 ]; then
                if [ "$a" -ne 0 ] && [ "$b" -ne 0 ]; then
                    refused=$((refused + 1))
                else
                    echo "DIFFERS: $name $tag $extra: one build refused it ($(tail -1 "$work/old.err") | $(tail -1 "$work/new.err"))"
                    differ=$((differ + 1))
                fi
                continue
            fi
            compared=$((compared + 1))
            if ! cmp -s "$out_old" "$out_new"; then
                echo "DIFFERS: $name $tag $extra"
                differ=$((differ + 1))
            fi
        done
    done
done
echo "same-images: $compared images compared, $differ differ, $refused refused by both builds"
[ "$differ" -eq 0 ]
