#!/usr/bin/env bash
# Render one image as a Slurm job array of N parts plus a merge job.
#
#   scripts/slurm-render.sh -n N [--max-running K] [--job-dir DIR] [--pathtracer BIN]
#                           [--sbatch-arg ARG]... [--dry-run] -- RENDER ARGS...
#
# RENDER ARGS are pathtracer's render flags, as for a one-machine render,
# including -f OUT.png and optionally --exr / --variance-exr: the array tasks
# get the rest plus `--part I/N --partial DIR/parts/part-I.ptp`, and the merge
# job writes those outputs with `pathtracer merge`, byte for byte what the
# one-machine render writes. Paths are used from the current directory, which
# must be on a file system every node shares (as must DIR and BIN).
#
# What is written to DIR (default: ./pt-job-<date>-<pid>): render.sh (the
# array task: `set -euo pipefail`, the renderer run as a child, not exec'ed,
# so a killed renderer makes the task exit 137, which a site's RequeueExit=137
# requeues), merge.sh (checks that every part is there and intact with
# `pathtracer verify`, lists the missing and damaged ones with the sbatch line
# that re-renders just those, then merges), parts/, logs/.
# Then it submits
#   sbatch --parsable --requeue --array=0-(N-1)[%K] DIR/render.sh
#   sbatch --parsable --dependency=afterany:ARRAY_ID DIR/merge.sh
# (afterany, not afterok: Slurm 22.05's afterok never fires after a task was
# requeued on its exit code; merge.sh checks completeness itself). With
# --dry-run the scripts are written and the two commands printed, not run,
# for sites that submit through wrappers of their own.
set -euo pipefail

usage() { sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
die() { echo "slurm-render: error: $*" >&2; exit 2; }

n=""; max_running=""; job_dir=""; bin=""; dry_run=0; sbatch_args=()
while (($#)); do
    case "$1" in
        -n) n="${2:-}"; shift 2 ;;
        --max-running) max_running="${2:-}"; shift 2 ;;
        --job-dir) job_dir="${2:-}"; shift 2 ;;
        --pathtracer) bin="${2:-}"; shift 2 ;;
        --sbatch-arg) sbatch_args+=("${2:-}"); shift 2 ;;
        --dry-run) dry_run=1; shift ;;
        -h|--help) usage ;;
        --) shift; break ;;
        *) die "unknown option '$1' (render flags go after --)" ;;
    esac
done
[[ "$n" =~ ^[1-9][0-9]*$ ]] || die "-n N: the number of parts must be a positive integer (got '${n}')"
[[ -z "$max_running" || "$max_running" =~ ^[1-9][0-9]*$ ]] || die "--max-running K: expected a positive integer (got '$max_running')"

# Split the render arguments: outputs go to the merge, the rest to the tasks.
render_args=(); out_png=""; merge_outputs=()
while (($#)); do
    case "$1" in
        -f) out_png="${2:-}"; shift 2 ;;
        --exr|--variance-exr) [[ -n "${2:-}" ]] || die "$1 needs a file"; merge_outputs+=("$1" "$2"); shift 2 ;;
        --part|--partial|--split) die "$1 is set by this script" ;;
        *) render_args+=("$1"); shift ;;
    esac
done
[[ -n "$out_png" ]] || die "the render arguments need -f OUT.png (the merged image)"

if [[ -z "$bin" ]]; then
    here="$(cd "$(dirname "$0")/.." && pwd)"
    if [[ -x "$here/target/release/pathtracer" ]]; then bin="$here/target/release/pathtracer"
    else bin="$(command -v pathtracer || true)"; fi
fi
[[ -n "$bin" && -x "$bin" ]] || die "no pathtracer binary (build it with cargo build --release, or pass --pathtracer BIN)"
bin="$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")"

job_dir="${job_dir:-$PWD/pt-job-$(date +%Y%m%d-%H%M%S)-$$}"
mkdir -p "$job_dir/parts" "$job_dir/logs"
job_dir="$(cd "$job_dir" && pwd)"
cwd="$PWD"
q() { (($#)) && printf '%q ' "$@"; return 0; }

cat > "$job_dir/render.sh" <<EOF
#!/usr/bin/env bash
#SBATCH --job-name=pt-render
#SBATCH --output=$job_dir/logs/render-%A_%a.out
#SBATCH --chdir=$cwd
# One part of a split render (written by scripts/slurm-render.sh).
set -euo pipefail
i="\${SLURM_ARRAY_TASK_ID:?render.sh runs as a Slurm array task}"
# Not exec'ed: a killed renderer then makes this script exit 137, which
# RequeueExit=137 requeues, and set -e keeps it from reporting success.
$(q "$bin" "${render_args[@]}") --part "\$i/$n" --partial "$job_dir/parts/part-\$i.ptp"
EOF

cat > "$job_dir/merge.sh" <<EOF
#!/usr/bin/env bash
#SBATCH --job-name=pt-merge
#SBATCH --output=$job_dir/logs/merge-%j.out
#SBATCH --chdir=$cwd
# Merge the parts of a split render (written by scripts/slurm-render.sh).
set -euo pipefail
# Every part must be there and intact (pathtracer verify checks its
# checksums); the others are listed with the line that re-renders them.
missing=(); damaged=(); redo=()
for ((i = 0; i < $n; i++)); do
    part="$job_dir/parts/part-\$i.ptp"
    if [[ ! -s "\$part" ]]; then
        missing+=("\$i"); redo+=("\$i")
    elif ! why="\$($(q "$bin") verify "\$part" 2>&1 >/dev/null)"; then
        echo "merge: part \$i is damaged: \$(head -n 1 <<<"\$why")" >&2
        damaged+=("\$i"); redo+=("\$i")
    fi
done
if ((\${#redo[@]})); then
    list="\$(IFS=,; echo "\${redo[*]}")"
    if ((\${#missing[@]})); then echo "merge: \${#missing[@]} of $n parts are missing: \$(IFS=,; echo "\${missing[*]}")" >&2; fi
    if ((\${#damaged[@]})); then echo "merge: \${#damaged[@]} of $n parts are damaged: \$(IFS=,; echo "\${damaged[*]}")" >&2; fi
    echo "merge: re-render just those, then merge again:" >&2
    echo "  JID=\\\$(sbatch --parsable --requeue --array=\$list $job_dir/render.sh) && sbatch --dependency=afterany:\\\$JID $job_dir/merge.sh" >&2
    exit 1
fi
parts=()
for ((i = 0; i < $n; i++)); do parts+=("$job_dir/parts/part-\$i.ptp"); done
$(q "$bin") merge "\${parts[@]}" $(q -f "$out_png" "${merge_outputs[@]}")
EOF
chmod +x "$job_dir/render.sh" "$job_dir/merge.sh"

array="0-$((n - 1))${max_running:+%$max_running}"
render_cmd=(sbatch --parsable --requeue "--array=$array" "${sbatch_args[@]}" "$job_dir/render.sh")
if ((dry_run)); then
    echo "# job directory: $job_dir"
    echo "JID=\$($(q "${render_cmd[@]}"))"
    echo "JID=\${JID%%;*}"
    echo "sbatch --parsable --dependency=afterany:\$JID $(q "${sbatch_args[@]}")$(q "$job_dir/merge.sh")"
    exit 0
fi
jid="$("${render_cmd[@]}")"
jid="${jid%%;*}"
mid="$(sbatch --parsable "--dependency=afterany:$jid" "${sbatch_args[@]}" "$job_dir/merge.sh")"
mid="${mid%%;*}"
echo "submitted: render array $jid ($n parts), merge $mid; job directory $job_dir; image $out_png"
echo "$jid $mid" > "$job_dir/job-ids"
