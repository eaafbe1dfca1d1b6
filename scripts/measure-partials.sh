#!/usr/bin/env bash
# What checking partials costs on a 1920x1080 frame: renders the built-in
# scene as a 2-part sample split (each part holds the whole frame's sums,
# 307 MB), then times `pathtracer verify` (both checksums) and `pathtracer
# merge` (which checks the records as it sums them), best of 3 from the
# page cache, and prints a Markdown table.
#   scripts/measure-partials.sh [--pathtracer BIN] [RENDER FLAGS...]
# (--pathtracer: another build's binary, to compare; an older binary
# without `verify` gets a dash in that row.)
set -euo pipefail
cd "$(dirname "$0")/.."
pt=""
if [[ "${1:-}" == --pathtracer ]]; then pt="$(realpath "$2")"; shift 2; fi
if [[ -z "$pt" ]]; then cargo build --release -q; pt="$PWD/target/release/pathtracer"; fi
dir="$(mktemp -d /tmp/pt-measure-partials.XXXXXX)"
trap 'rm -rf "$dir"' EXIT
cd "$dir"
for i in 0 1; do "$pt" -r 1920 1080 -s 2 -m 1 "$@" --part "$i/2" --partial "p$i.ptp" >/dev/null; done
best() { # best wall seconds of 3 runs of "$@"
    local b=""
    for _ in 1 2 3; do
        local t0 t1; t0=$(date +%s%N); "$@" >/dev/null; t1=$(date +%s%N)
        b=$(awk -v a="$b" -v t="$(( (t1 - t0) / 1000 ))" 'BEGIN { t /= 1e6; print (a == "" || t < a) ? t : a }')
    done
    echo "$b"
}
size=$(stat -c %s p0.ptp)
if "$pt" verify p0.ptp >/dev/null 2>&1; then v=$(best "$pt" verify p0.ptp p1.ptp); else v="-"; fi
m=$(best "$pt" merge p0.ptp p1.ptp -f out.png)
c=$(best cat p0.ptp p1.ptp)
echo "1920x1080, 2 parts of $((size / 1000000)) MB, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
echo
echo "| step | seconds | GB/s |"
echo "|---|---:|---:|"
for row in "read both files (cat) $c" "verify both (checksums only) $v" "merge (checksums, sums, PNG) $m"; do
    t="${row##* }"; name="${row% *}"
    echo "| $name | $t | $(awk -v s="$size" -v t="$t" 'BEGIN { if (t == "-") print "-"; else printf "%.2f", 2 * s / t / 1e9 }') |"
done
