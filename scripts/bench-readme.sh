#!/usr/bin/env bash
# Runs `pathtracer bench` (standard scenes, all backends) into docs/benchmarks/bench.md and
# docs/benchmarks/bench.csv, with the run's date and commit as the first line, then pastes the
# headline table (scripts/bench-summary.py) into README.md between the bench markers, so that
# every performance number in the documentation is the benchmark's output, never typed. Built
# with the peer BVH libraries (--features peers). Takes about three hours on 2 cores (nine
# contenders; the 1M-10M-triangle generated scenes; every scene's rays of four kinds one at a
# time and in batches). Each finished scene is kept in target/bench-readme (`bench --resume`):
# cut short, the script run again with the same binary continues where it stopped; the folder
# is removed once the tables are written. `--paste-only` skips the run and pastes from the
# existing files; other arguments go to `pathtracer bench`.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" != "--paste-only" ]; then
    cargo build --release -q --features peers
    measured="$(python3 validation/provenance.py)"
    ./target/release/pathtracer bench --resume target/bench-readme --markdown docs/benchmarks/bench.md --csv docs/benchmarks/bench.csv "$@"
    rm -rf target/bench-readme
    embree="$(./target/release/pathtracer --version | sed -n 's/^embree[34]: //p' | paste -sd '&' | sed 's/&/ and /')"
    [ -n "$embree" ] || embree="no Embree"
    sed -i "1i $measured\n\nWritten by \`scripts/bench-readme.sh\` ($embree)." docs/benchmarks/bench.md
fi
python3 scripts/bench-summary.py --paste
