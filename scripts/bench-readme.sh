#!/usr/bin/env bash
# Runs `pathtracer bench` (standard scenes, all backends) and puts its Markdown output into
# docs/bench.md and into README.md between the bench markers, so that the README's performance
# tables are the benchmark's output, never typed. Built with the peer BVH libraries
# (--features peers: obvhs). Takes about 21 minutes on 2 cores (the 1M-10M-triangle
# generated scenes). `--paste-only` skips the run and pastes the existing docs/bench.md.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" != "--paste-only" ]; then
    cargo build --release -q --features peers
    ./target/release/pathtracer bench --markdown docs/bench.md --csv docs/bench.csv "$@"
fi
python3 - <<'PY'
import re
readme = open("README.md").read()
bench = open("docs/bench.md").read()
start, end = "<!-- bench:start (scripts/bench-readme.sh writes this part) -->", "<!-- bench:end -->"
if start not in readme or end not in readme:
    raise SystemExit("README.md: bench markers missing")
head, rest = readme.split(start, 1)
_, tail = rest.split(end, 1)
open("README.md", "w").write(head + start + "\n\n" + bench.strip() + "\n\n" + end + tail)
print("README.md: bench tables updated from docs/bench.md")
PY
