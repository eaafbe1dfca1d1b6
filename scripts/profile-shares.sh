#!/usr/bin/env bash
# Where a render's work goes: one single-threaded render under valgrind's
# callgrind, its instructions summed into traversal (the BVH and primitive
# tests), light sampling (lights, spherical rectangles and triangles, cones,
# lune, environment, and the libm trigonometry they call), the sampler
# (Sobol and independent draws), shading and path (BSDFs, describing hits,
# the path loop, camera rays, pixel sums, buffers) and the rest (start-up,
# scene loading, BVH build, image output).
#
#   scripts/profile-shares.sh [PATHTRACER ARGS...]     (default: the built-in scene at -m 5)
#
# Instructions, not seconds: callgrind counts the same on any machine and
# whatever else runs, and attributes inlined code to the file it comes from
# (so the Sobol draws inlined into the path code still count as the
# sampler's). Seconds per instruction differ between categories (traversal
# is SIMD-dense; light sampling waits on divisions and square roots), so
# read the shares next to a `perf` profile when timing matters.
set -euo pipefail
cd "$(dirname "$0")/.."
command -v valgrind >/dev/null || { DEBIAN_FRONTEND=noninteractive apt-get install -y -qq valgrind >/dev/null; }
cargo build --release --quiet
args=("$@")
((${#args[@]})) || args=(-r 128 96 --keep-fov -m 5 -s 16)
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
valgrind --tool=callgrind --callgrind-out-file="$work/cg.out" target/release/pathtracer "${args[@]}" -t 1 -f "$work/out.png" >/dev/null 2>"$work/log"
echo "pathtracer ${args[*]} -t 1 ($(lscpu | sed -n 's/^Model name: *//p' | head -1)): instruction shares"
callgrind_annotate "$work/cg.out" 2>/dev/null | python3 -c '
import re, sys
share, total = {}, None
order = ["traversal", "light sampling", "sampler", "shading and path", "start-up, load, build, output"]
def category(path, func):
    if "/src/sampler/" in path or path.endswith("/src/rng.rs"):
        return "sampler"
    if "/src/light/" in path:
        return "light sampling"
    if "/src/accel/" in path or "/src/geometry/" in path:
        return "traversal"
    if any(p in path for p in ("/src/bsdf/", "/src/scene/interaction.rs", "/src/render/", "/src/camera.rs", "/src/sampling.rs")):
        return "shading and path"
    # Library code (core, glam, libm, libc) counts where it was called from.
    if re.search(r"sampler::|Sampler::", func):
        return "sampler"
    if path.endswith("uint_macros.rs") and re.search(r"direct_terms|continuation|sample_tile", func):
        return "sampler"  # the Sobol bit reversals inlined into the path code
    if re.search(r"accel::|WideBvh|Prim::intersect|Frustum|geometry::", func):
        return "traversal"
    if re.search(r"light::|SphericalRect|SphericalTriangle|SphereCone|lune|EnvMap|atan2|acos|sincos|__sin|__cos", func):
        return "light sampling"
    if re.search(r"render::|path::|wavefront|PixelState|bsdf::|Bsdf|Interaction|camera::|memcpy|memmove|malloc|_int_|free|tanf", func):
        return "shading and path"
    return order[-1]
for line in sys.stdin:
    m = re.match(r"\s*([\d,]+) \(\s*[\d.]+%\)\s+(\S+?):(.*)$", line)
    if not m:
        continue
    n = int(m.group(1).replace(",", ""))
    if m.group(2) == "PROGRAM" or "PROGRAM TOTALS" in line:
        total = n
        continue
    cat = category(m.group(2), m.group(3))
    share[cat] = share.get(cat, 0) + n
total = total or sum(share.values())
for c in order:
    print(f"  {c:32s} {100 * share.get(c, 0) / total:5.1f} %")
print(f"  {total / 1e6:.0f} M instructions")
'
