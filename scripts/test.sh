#!/usr/bin/env bash
# The project's test command (README, CI): installs missing system packages
# (Embree 3 from Debian, Embree 4 into third_party/), runs the whole suite
# optimised with both Embrees (unit, whole-program, fuzz, documentation and
# doc tests), checks that builds with both or either Embree hidden from
# build.rs still pass (the whole suite, and the Embree-dependent tests), builds the API documentation
# with warnings as errors, renders a split image through a real two-node
# Slurm cluster on loopback (installs Debian's slurm and munge when missing),
# then runs the validation harness's quick tier (native, Embree 3 and
# Embree 4 against Mitsuba 3, Blender Cycles and POV-Ray).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
# The reference renderers too, before the suite: tests/harness.rs runs the harness's exporters and statistics.
bash validation/setup

echo "== test suite (with Embree 3 and Embree 4) =="
# With the peer BVH libraries built in (tests/peers.rs checks they answer as native does).
PATHTRACER_REQUIRE_EMBREE=3,4 cargo test --release --features peers

# The passes with Embree hidden share one target folder: their dependencies
# are built once, and only this crate again for each setting.
echo "== test suite with both Embrees hidden (PATHTRACER_NO_EMBREE=all) =="
# The BVH-vs-brute oracle test touches no Embree code and takes two minutes,
# so this pass skips it; everything else runs again.
PATHTRACER_NO_EMBREE=all CARGO_TARGET_DIR=target/hidden cargo test --release -- --skip native_bvh_matches_brute_force

echo "== the Embree tests with one major hidden at a time (PATHTRACER_NO_EMBREE=3, then 4) =="
# What depends on which Embree is built: the cross-checks, the CLI's
# backends, split renders and the documented commands, with the other major
# required.
PATHTRACER_NO_EMBREE=3 PATHTRACER_REQUIRE_EMBREE=4 CARGO_TARGET_DIR=target/hidden cargo test --release \
    --test embree_crosscheck --test cli --test split --test docs
PATHTRACER_NO_EMBREE=4 PATHTRACER_REQUIRE_EMBREE=3 CARGO_TARGET_DIR=target/hidden cargo test --release \
    --test embree_crosscheck --test cli --test split --test docs

echo "== API documentation (cargo doc --no-deps, warnings are errors) =="
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --release --quiet

echo "== split renders on a real Slurm cluster (two slurmd on loopback; scripts/slurm-e2e.sh) =="
bash scripts/slurm-e2e.sh

echo "== validation harness, quick tier (Mitsuba 3, Blender Cycles and POV-Ray references) =="
PATHTRACER_REQUIRE_EMBREE=3,4 bash validation/run quick
