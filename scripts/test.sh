#!/usr/bin/env bash
# The project's test command (README, CI): installs missing system packages,
# runs the whole suite optimised with Embree (unit, whole-program, fuzz,
# documentation and doc tests), checks that a build with Embree hidden from
# build.rs still passes the rest of the suite, builds the API documentation
# with warnings as errors, renders a split image through a real two-node
# Slurm cluster on loopback (installs Debian's slurm and munge when missing),
# then runs the validation harness's quick tier (both backends against
# Mitsuba 3, Blender Cycles and POV-Ray).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh

echo "== test suite (with Embree) =="
# With the peer BVH libraries built in (tests/peers.rs checks they answer as native does).
PATHTRACER_REQUIRE_EMBREE=1 cargo test --release --features peers

echo "== test suite with Embree hidden (PATHTRACER_NO_EMBREE=1) =="
# The BVH-vs-brute oracle test touches no Embree code and takes two minutes,
# so this second pass skips it; everything else runs again.
PATHTRACER_NO_EMBREE=1 CARGO_TARGET_DIR=target/no-embree cargo test --release -- --skip native_bvh_matches_brute_force

echo "== API documentation (cargo doc --no-deps, warnings are errors) =="
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --release --quiet

echo "== split renders on a real Slurm cluster (two slurmd on loopback; scripts/slurm-e2e.sh) =="
bash scripts/slurm-e2e.sh

echo "== validation harness, quick tier (Mitsuba 3, Blender Cycles and POV-Ray references) =="
bash validation/run quick
