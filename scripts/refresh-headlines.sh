#!/usr/bin/env bash
# Regenerates the README's three headline tables, and the evidence pages they summarise, from
# one commit on one machine, so that every table names the same commit and CPU:
#   0. the references' images for both tiers into the harness's cache (validation/warm_cache.py;
#      nothing timed, and nothing to do where an earlier run left them);
#   1. speed of traversal: `pathtracer bench` with the peers (scripts/bench-readme.sh) into
#      docs/benchmarks/bench.md and .csv, and the README's bench table;
#   2. error at equal time: the harness's full tier with the native backend (the README's error
#      table is native's; the Embree backends render the same images, and the bench times their
#      traversal), then validation/speed_vs_error.py into docs/validation/speed-vs-error.{md,csv}
#      and the README's table (`--full-runs 2` runs it twice and tables the worse ratio);
#   3. correctness: the harness's quick tier with every backend, its verdicts into the README and
#      docs/validation/README.md (validation/verdict_summary.py).
# Refuses a tree with uncommitted changes (the tables must name a commit that reproduces them)
# and checks at the end that the commit did not change under it. On 2 cores (a Zen 3 EPYC,
# 2026-12-04): 2.5-3 h of bench (grass 2M alone about an hour), about 110 minutes of each
# full-tier run (half an hour of path-traced cases, the rest its BDPT axis) and 5 of quick tier
# once the references are cached (40-60 minutes more to render them after the exporters change:
# step 0, which may run earlier, on its own). The bench keeps its finished parts
# (target/bench-readme), so a cut run continues on the same binary and CPU; the tiers start
# over. Run it on a quiet machine. Commit the changed files afterwards.
#
#   scripts/refresh-headlines.sh [--skip-bench] [--skip-error] [--skip-verdicts] [--full-runs N]
set -euo pipefail
cd "$(dirname "$0")/.."
python3 validation/provenance.py --clean >/dev/null
commit="$(git rev-parse HEAD)"
skip=" $* "
full_runs=1
while [ $# -gt 0 ]; do
    case "$1" in
        --full-runs) full_runs="$2"; shift 2 ;;
        --skip-bench|--skip-error|--skip-verdicts) shift ;;
        *) echo "refresh-headlines: unknown argument $1" >&2; exit 2 ;;
    esac
done
runs="$(mktemp -d)"
trap 'rm -rf "$runs"' EXIT

echo "== 0/3 the references' images (validation/warm_cache.py) =="
bash validation/setup
cargo build --release -q
validation/.venv/bin/python validation/warm_cache.py full
validation/.venv/bin/python validation/warm_cache.py quick
if [[ "$skip" != *" --skip-bench "* ]]; then
    echo "== 1/3 bench (scripts/bench-readme.sh) =="
    bash scripts/bench-readme.sh
fi
if [[ "$skip" != *" --skip-error "* ]]; then
    for i in $(seq "$full_runs"); do
        echo "== 2/3 full tier, run $i of $full_runs =="
        bash validation/run full --backends native || true   # the verdicts are read from summary.json below
        cp validation/out/summary.json "$runs/full-$i.json"
    done
    validation/.venv/bin/python validation/speed_vs_error.py "$runs"/full-*.json \
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
