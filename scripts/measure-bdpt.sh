#!/usr/bin/env bash
# BDPT (every light subpath, and --bdpt-light-paths specular: bdpt:specular)
# against our path tracer at equal time (validation/bdpt_vs_path.py) on
# the scenes of docs/design/bdpt.md: the diffuse box, the caustic under
# CBspheres' glass sphere at -m 8, the floor around CBgems' gems. Appends the
# ratios to docs/validation/bdpt-vs-path.csv, keeps both curves of every row in
# docs/validation/bdpt-vs-path.json and plots them in
# docs/validation/bdpt-vs-path.svg. About 8 minutes on 2 cores; run it with
# nothing else running (the ratios are timings).
#
#   scripts/measure-bdpt.sh [--seeds N] [--ladder 4,16,64]
set -euo pipefail
cd "$(dirname "$0")/.."
seeds=5; ladder=4,16,64
while (($#)); do
    case "$1" in
        --seeds) seeds=$2; shift 2 ;;
        --ladder) ladder=$2; shift 2 ;;
        *) echo "measure-bdpt.sh: unknown argument $1 (expected --seeds N, --ladder A,B,C)" >&2; exit 2 ;;
    esac
done
bash validation/setup >/dev/null
cargo build --release -q
scenes=scenes/cs184/sky
out=docs/validation/bdpt-vs-path
run() {
    validation/.venv/bin/python validation/bdpt_vs_path.py "$@" --size 256 192 --ladder "$ladder" --seeds "$seeds" --integrators path,bdpt,bdpt:specular \
        --csv "$out.csv" --curves "$out.json" --svg "$out.svg"
}
run "$scenes/cs184/sky/CBspheres_lambertian.dae" -m 5
# CBspheres: the floor's caustic alone (floor_caustic), and the window of the
# earlier runs, which also holds the bottom of the ball (caustic_and_ball).
run "$scenes/CBspheres.dae" -m 8 --region 144 143 28 5 --region 135 138 36 12 --region-names floor_caustic,caustic_and_ball
run "$scenes/CBgems.dae" -m 5 --region 96 128 64 22 --region-names floor_around_gems
