#!/usr/bin/env bash
# Regenerates the README's three headline tables, and the evidence pages they summarise, from
# one commit on one machine, so that every table names the same commit and CPU:
#   1. speed of traversal: `pathtracer bench` with the peers (scripts/bench-readme.sh) into
#      docs/benchmarks/bench.md and .csv, and the README's bench table;
#   2. error at equal time: the harness's full tier twice (validation/run full), then
#      validation/speed_vs_error.py over both runs into docs/validation/speed-vs-error.{md,csv}
#      and the README's table (path tracer, BDPT and light tracing rows);
#   3. correctness: the harness's quick tier, its verdicts into the README and
#      docs/validation/README.md (validation/verdict_summary.py).
# Refuses a tree with uncommitted changes (the tables must name a commit that reproduces them)
# and checks at the end that the commit did not change under it. Takes about two and a half
# hours on 2 cores; run it on a quiet machine. Commit the changed files afterwards.
#
#   scripts/refresh-headlines.sh [--skip-bench] [--skip-error] [--skip-verdicts]
set -euo pipefail
cd "$(dirname "$0")/.."
python3 validation/provenance.py --clean >/dev/null
commit="$(git rev-parse HEAD)"
skip=" $* "
runs="$(mktemp -d)"
trap 'rm -rf "$runs"' EXIT

if [[ "$skip" != *" --skip-bench "* ]]; then
    echo "== 1/3 bench (scripts/bench-readme.sh) =="
    bash scripts/bench-readme.sh
fi
if [[ "$skip" != *" --skip-error "* ]]; then
    for i in 1 2; do
        echo "== 2/3 full tier, run $i of 2 =="
        bash validation/run full || true   # the verdicts are read from summary.json below
        cp validation/out/summary.json "$runs/full-$i.json"
    done
    validation/.venv/bin/python validation/speed_vs_error.py "$runs/full-1.json" "$runs/full-2.json" \
        --csv docs/validation/speed-vs-error.csv --svg docs/validation/speed-vs-error.svg \
        --cases CBspheres_lambertian_m5,CBgems_m5,bunny_unlit_m3_env_studio --paste
fi
if [[ "$skip" != *" --skip-verdicts "* ]]; then
    echo "== 3/3 quick tier =="
    bash validation/run quick || true
    python3 validation/verdict_summary.py validation/out/summary.json --paste
fi
if [ "$(git rev-parse HEAD)" != "$commit" ]; then
    echo "refresh-headlines: HEAD moved during the run; the tables are not from one commit" >&2
    exit 1
fi
echo "refresh-headlines: README.md and the evidence pages regenerated at $(git rev-parse --short=12 HEAD); review and commit them"
