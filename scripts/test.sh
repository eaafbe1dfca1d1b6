#!/usr/bin/env bash
# The project's test command (README, CI): installs missing system packages
# (Embree 3 from Debian, Embree 4 into third_party/), runs the whole suite
# optimised with both Embrees (unit, whole-program, fuzz, documentation and
# doc tests), checks that builds with both or either Embree hidden from
# build.rs still pass (every target built, the Embree-dependent tests run),
# builds the API documentation
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

# The passes with Embree hidden build with the same features in the same
# target folder as the first pass: the dependencies are not built again, only
# this crate (its build script sees the new setting).
stage "test suite with both Embrees hidden (PATHTRACER_NO_EMBREE=all)"
# Every target is built; the tests run are those whose code, or the code they
# drive, depends on which backends this build has: the library's units, the
# CLI (backend choice and messages), the documented commands, batches and
# hard cases over every backend, split renders, validate's geometry checks,
# the cross-checks (which report themselves skipped). The rest (light
# transport, BDPT, materials, samplers, loaders, fuzz, the harness, the peer
# libraries against native, the BVH-vs-brute oracle) trace native, brute
# force and the peers only once Embree is hidden: the same computations as
# the first pass, not run twice.
PATHTRACER_NO_EMBREE=all cargo test --release --features peers --no-run
PATHTRACER_NO_EMBREE=all cargo test --release --features peers --lib \
    --test cli --test docs --test batches --test hard_cases --test split --test validate --test embree_crosscheck

stage "the Embree tests with one major hidden at a time (PATHTRACER_NO_EMBREE=3, then 4)"
# What depends on which Embree is built: the cross-checks, the CLI's
# backends, split renders and the documented commands, with the other major
# required.
PATHTRACER_NO_EMBREE=3 PATHTRACER_REQUIRE_EMBREE=4 cargo test --release --features peers \
    --test embree_crosscheck --test cli --test split --test docs
PATHTRACER_NO_EMBREE=4 PATHTRACER_REQUIRE_EMBREE=3 cargo test --release --features peers \
    --test embree_crosscheck --test cli --test split --test docs

stage "API documentation (cargo doc --no-deps, warnings are errors)"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --release --quiet

stage "split renders on a real Slurm cluster (two slurmd on loopback; scripts/slurm-e2e.sh)"
bash scripts/slurm-e2e.sh

stage "validation harness, quick tier (Mitsuba 3, Blender Cycles and POV-Ray references)"
PATHTRACER_REQUIRE_EMBREE=3,4 bash validation/run quick
