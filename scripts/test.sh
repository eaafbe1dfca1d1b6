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

# Each stage's wall time, printed as a table when the script ends (passed or
# not), so a CI log says where its minutes went.
stage_names=(); stage_secs=(); stage_start=$SECONDS; stage_now="set-up (Embree, libclang, the reference renderers)"
stage() {
    stage_names+=("$stage_now"); stage_secs+=($((SECONDS - stage_start)))
    stage_now="$1"; stage_start=$SECONDS
    echo "== $1 =="
}
stage_report() {
    local rc=$?
    stage_names+=("$stage_now"); stage_secs+=($((SECONDS - stage_start)))
    echo "== stage times (wall clock, $(nproc) CPUs) =="
    for i in "${!stage_names[@]}"; do
        printf '%6d s  %s\n' "${stage_secs[$i]}" "${stage_names[$i]}"
    done
    printf '%6d s  total%s\n' "$SECONDS" "$([ $rc -eq 0 ] || echo ", stopped by a failure in the last stage")"
}
trap stage_report EXIT

bash scripts/install-deps.sh
# The reference renderers too, before the suite: tests/harness.rs runs the harness's exporters and statistics.
bash validation/setup

stage "test suite (with Embree 3 and Embree 4)"
# With the peer BVH libraries built in (tests/peers.rs checks they answer as native does).
PATHTRACER_REQUIRE_EMBREE=3,4 cargo test --release --features peers

# The passes with Embree hidden share one target folder: their dependencies
# are built once, and only this crate again for each setting.
stage "test suite with both Embrees hidden (PATHTRACER_NO_EMBREE=all)"
# The BVH-vs-brute oracle test touches no Embree code and takes two minutes,
# so this pass skips it; everything else runs again.
PATHTRACER_NO_EMBREE=all CARGO_TARGET_DIR=target/hidden cargo test --release -- --skip native_bvh_matches_brute_force

stage "the Embree tests with one major hidden at a time (PATHTRACER_NO_EMBREE=3, then 4)"
# What depends on which Embree is built: the cross-checks, the CLI's
# backends, split renders and the documented commands, with the other major
# required.
PATHTRACER_NO_EMBREE=3 PATHTRACER_REQUIRE_EMBREE=4 CARGO_TARGET_DIR=target/hidden cargo test --release \
    --test embree_crosscheck --test cli --test split --test docs
PATHTRACER_NO_EMBREE=4 PATHTRACER_REQUIRE_EMBREE=3 CARGO_TARGET_DIR=target/hidden cargo test --release \
    --test embree_crosscheck --test cli --test split --test docs

stage "API documentation (cargo doc --no-deps, warnings are errors)"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --release --quiet

stage "split renders on a real Slurm cluster (two slurmd on loopback; scripts/slurm-e2e.sh)"
bash scripts/slurm-e2e.sh

stage "validation harness, quick tier (Mitsuba 3, Blender Cycles and POV-Ray references)"
PATHTRACER_REQUIRE_EMBREE=3,4 bash validation/run quick
