#!/usr/bin/env bash
# End-to-end test of split rendering on a real Slurm cluster, on this machine.
#
# Installs Debian's Slurm and munge when missing, then, inside network, PID
# and mount namespaces of its own (loopback only; the kernel ends every
# process left in the PID namespace when this script ends), starts munged,
# slurmctld and two `slurmd -N` nodes with all their state in a temp dir,
# and proves, with scripts/slurm-render.sh and the real renderer:
#   (a) an N = 8 split render through the array job and the merge job equals
#       the local render of the same scene, settings and seed, byte for byte;
#   (b) with one task's renderer SIGKILLed and one node killed mid-run, the
#       array still completes (requeue) and the merged images are identical;
#   (c) merge refuses an incomplete and an overlapping set of partials, and
#       the merge job names the missing parts and the sbatch line for them;
#   (d) a part damaged on disk after its task finished is refused by name,
#       and the re-render line the merge job prints restores the images
#       byte for byte.
# Every daemon is stopped by the PID recorded at its start; the script then
# checks that nothing of the cluster is left running.
#
# Needs root (namespaces, daemons, apt). Under CI it must run; elsewhere,
# without root, it says SKIPPED and exits 0.
set -euo pipefail
cd "$(dirname "$0")/.."
repo="$PWD"

if [[ "${PT_SLURM_E2E_INSIDE:-}" != 1 ]]; then
    if [[ $(id -u) != 0 ]]; then
        if [[ -n "${CI:-}" ]]; then echo "slurm-e2e: FAILED: CI must run this as root" >&2; exit 1; fi
        echo "slurm-e2e: SKIPPED (needs root for namespaces and the Slurm daemons)" >&2
        exit 0
    fi
    if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v sbatch >/dev/null || ! command -v munged >/dev/null \
        || ! command -v ip >/dev/null || ! command -v unshare >/dev/null; then
        echo "== installing Slurm and munge (Debian packages) =="
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge iproute2 util-linux procps >/dev/null
    fi
    cargo build --release --quiet
    export PT_SLURM_E2E_INSIDE=1
    exec unshare --net --pid --mount --fork --mount-proc "$0" "$@"
fi

t_start=$(date +%s%N)
since() { awk -v a="$1" -v b="$(date +%s%N)" 'BEGIN { printf "%.1f", (b - a) / 1e9 }'; }
log() { printf '%6ss  %s\n' "$(since "$t_start")" "$*"; }
fail() { log "FAILED: $*"; dump_logs; exit 1; }

S="$(mktemp -d /tmp/pt-slurm-e2e.XXXXXX)"
chmod 755 "$S"
mkdir -p "$S/munge" "$S/log" "$S/state" "$S/spool/n1" "$S/spool/n2" "$S/work"
chmod 755 "$S/munge"
export SLURM_CONF="$S/slurm.conf"
declare -A pid=()

dump_logs() {
    for f in "$S"/log/*.log "$S"/work/*/logs/*; do
        [[ -f "$f" ]] || continue
        echo "---- $f (last lines)"; tail -n 15 "$f"
    done
}

# Stop every daemon by its recorded PID (nodes, then the controller, then
# munged), then make sure nothing of the cluster is left.
stop_all() {
    for name in slurmd-n1 slurmd-n2 slurmctld munged; do
        local p="${pid[$name]:-}"
        [[ -n "$p" ]] && kill "$p" 2>/dev/null || true
    done
    for name in slurmd-n1 slurmd-n2 slurmctld munged; do
        local p="${pid[$name]:-}"
        [[ -n "$p" ]] && wait "$p" 2>/dev/null || true
    done
    pid=()
}
trap 'stop_all; rm -rf "$S"' EXIT

# --- networking: loopback, plus one address so that getaddrinfo(AI_ADDRCONFIG)
# finds IPv4 (slurmctld dies on "getaddrinfo() failed" with lo alone).
ip link set lo up
ip link add pt0 type veth peer name pt1
ip addr add 169.254.77.1/32 dev pt0
ip link set pt0 up

host="$(hostname -s)"
dd if=/dev/urandom of="$S/munge.key" bs=1024 count=1 status=none
chmod 400 "$S/munge.key"
cat > "$S/slurm.conf" <<EOF
ClusterName=pte2e
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=16817
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$S/munge/munge.socket.2,cred_expire=10
CredType=cred/munge
StateSaveLocation=$S/state
SlurmdSpoolDir=$S/spool/%n
SlurmctldPidFile=$S/slurmctld.pid
SlurmdPidFile=$S/slurmd-%n.pid
SlurmctldLogFile=$S/log/slurmctld.log
SlurmdLogFile=$S/log/slurmd-%n.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerParameters=batch_sched_delay=0,sched_min_interval=0,sched_interval=1,bf_interval=1
SlurmdTimeout=10
ReturnToService=2
RequeueExit=137
MinJobAge=600
KillWait=2
InactiveLimit=0
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
NodeName=n1 NodeHostname=$host NodeAddr=127.0.0.1 Port=17001 CPUs=1 State=UNKNOWN
NodeName=n2 NodeHostname=$host NodeAddr=127.0.0.1 Port=17002 CPUs=1 State=UNKNOWN
PartitionName=main Nodes=n1,n2 Default=YES MaxTime=INFINITE State=UP
EOF

munged -F --force --socket="$S/munge/munge.socket.2" --key-file="$S/munge.key" --pid-file="$S/munged.pid" \
    --log-file="$S/log/munged.log" --seed-file="$S/munge.seed" 2>>"$S/log/munged.out" &
pid[munged]=$!
for _ in $(seq 50); do [[ -S "$S/munge/munge.socket.2" ]] && break; sleep 0.1; done
[[ -S "$S/munge/munge.socket.2" ]] || fail "munged did not start"
slurmctld -D -f "$S/slurm.conf" >>"$S/log/slurmctld.out" 2>&1 &
pid[slurmctld]=$!
start_node() {
    slurmd -D -N "$1" -f "$S/slurm.conf" >>"$S/log/slurmd-$1.out" 2>&1 &
    pid[slurmd-$1]=$!
}
start_node n1
start_node n2
idle=0
for _ in $(seq 100); do
    if [[ "$(sinfo -h -N -o '%N %t' 2>/dev/null | grep -c ' idle$' || true)" == 2 ]]; then idle=1; break; fi
    sleep 0.1
done
((idle)) || fail "the two nodes did not come up idle: $(sinfo -N 2>&1 | tr '\n' ';')"
log "cluster up: munged, slurmctld, slurmd n1 and n2 idle (pids ${pid[*]})"

pt="$repo/target/release/pathtracer"

# Wait for a job to end; print its final state.
wait_job() {
    local id="$1" limit="$2" t=0 state=""
    while ((t < limit * 5)); do
        state="$(scontrol show job "$id" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | head -1 | cut -d= -f2)"
        case "$state" in COMPLETED|FAILED|CANCELLED|TIMEOUT|NODE_FAIL|OUT_OF_MEMORY) echo "$state"; return 0 ;; esac
        sleep 0.2; t=$((t + 1))
    done
    echo "TIMEOUT_WAITING($state)"
}

# The renderer's pid for part I (the newest, when requeued), or nothing.
renderer_pid() { pgrep -n -f -- "--part $1/$2 " || true; }

# Every process below $1, deepest first, then $1.
tree() {
    local p
    for p in $(pgrep -P "$1" || true); do tree "$p"; done
    echo "$1"
}

same_images() { # local render dir, merged dir
    cmp -s "$1/img.png" "$2/img.png" \
        && { { [ ! -e "$1/img_rate.png" ] && [ ! -e "$2/img_rate.png" ]; } || cmp -s "$1/img_rate.png" "$2/img_rate.png"; } \
        && cmp -s "$1/img.exr" "$2/img.exr" && cmp -s "$1/var.exr" "$2/var.exr"
}

# ---------------------------------------------------------------- (a)
scene_a=(-r 96 72 -s 64 -m 3 -t 1 --seed 5)
mkdir -p "$S/work/local-a" "$S/work/a"
"$pt" "${scene_a[@]}" -f "$S/work/local-a/img.png" --exr "$S/work/local-a/img.exr" --variance-exr "$S/work/local-a/var.exr" >/dev/null
(cd "$S/work/a" && "$repo/scripts/slurm-render.sh" -n 8 --job-dir "$S/work/a/job" -- "${scene_a[@]}" -f img.png --exr img.exr --variance-exr var.exr) >/dev/null
read -r jid mid < "$S/work/a/job/job-ids"
state="$(wait_job "$mid" 120)"
[[ "$state" == COMPLETED ]] || fail "(a) merge job $mid ended $state"
same_images "$S/work/local-a" "$S/work/a" || fail "(a) merged images differ from the local render"
nodes="$(scontrol show job "$jid" 2>/dev/null | grep -o ' NodeList=n[0-9]' | sort | uniq -c | tr -s ' \n' ' ')"
log "(a) PASS: N=8 array $jid + merge $mid: PNG, rate PNG, EXR and variance EXR byte-identical to the local render (tasks on:$nodes)"

# ---------------------------------------------------------------- (b)
# Parts long enough to be killed mid-render (about 4 s each on one core).
scene_b=(-r 160 120 -s 256 -m 4 -t 1 --seed 9)
mkdir -p "$S/work/local-b" "$S/work/b"
t0=$(date +%s%N)
"$pt" "${scene_b[@]}" -f "$S/work/local-b/img.png" --exr "$S/work/local-b/img.exr" --variance-exr "$S/work/local-b/var.exr" >/dev/null
log "(b) local render: $(since "$t0") s"
(cd "$S/work/b" && "$repo/scripts/slurm-render.sh" -n 4 --job-dir "$S/work/b/job" -- "${scene_b[@]}" -f img.png --exr img.exr --variance-exr var.exr) >/dev/null
read -r jid mid < "$S/work/b/job/job-ids"
# Wait until two tasks render, one on each node.
victim_task=""; node_task=""
for _ in $(seq 150); do
    running="$(squeue -h -j "$jid" -t R -o '%K %N' 2>/dev/null || true)"
    victim_task="$(awk '$2 == "n1" {print $1; exit}' <<<"$running")"
    node_task="$(awk '$2 == "n2" {print $1; exit}' <<<"$running")"
    if [[ -n "$victim_task" && -n "$node_task" && -n "$(renderer_pid "$victim_task" 4)" && -n "$(renderer_pid "$node_task" 4)" ]]; then break; fi
    sleep 0.1
done
[[ -n "$victim_task" && -n "$node_task" ]] || fail "(b) never saw a task rendering on each node: $running"
sleep 1
rp="$(renderer_pid "$victim_task" 4)"
kill -9 "$rp"
log "(b) SIGKILL renderer of task $victim_task on n1 (pid $rp)"
# Kill node n2: its slurmd, and the step daemon, script and renderer of its task.
tid="$(squeue -h -j "${jid}_${node_task}" -o %A 2>/dev/null || true)"
stepd="$(pgrep -f "slurmstepd: \[$tid\.batch\]" | head -1 || true)"
victims="${pid[slurmd-n2]}"
[[ -n "$stepd" ]] && victims="$victims $(tree "$stepd" | tr '\n' ' ')"
rp2="$(renderer_pid "$node_task" 4)"
[[ -n "$rp2" ]] && victims="$victims $rp2"
victims="$(tr ' ' '\n' <<<"$victims" | sort -un | tr '\n' ' ')"
kill -9 $victims 2>/dev/null || true
wait "${pid[slurmd-n2]}" 2>/dev/null || true
unset 'pid[slurmd-n2]'
log "(b) killed node n2 running task $node_task: slurmd, slurmstepd, job script and renderer (pids $victims)"
# Bring n2 back once the controller has marked it down, as an admin would.
for _ in $(seq 600); do
    st="$(sinfo -h -N -n n2 -o '%t' 2>/dev/null || true)"
    [[ "$st" == down* ]] && break
    sleep 0.1
done
log "(b) n2 is '$st'; restarting its slurmd"
start_node n2
state="$(wait_job "$mid" 150)"
[[ "$state" == COMPLETED ]] || fail "(b) merge job $mid ended $state"
same_images "$S/work/local-b" "$S/work/b" || fail "(b) merged images differ from the local render"
requeues="$(for t in 0 1 2 3; do scontrol show job "${jid}_$t" 2>/dev/null | grep -o 'Restarts=[0-9]*'; done | sort | uniq -c | tr -s ' \n' ' ')"
log "(b) PASS: array $jid completed after the kills (restart counts:$requeues); merged images byte-identical"

# ---------------------------------------------------------------- (c)
parts=("$S/work/b/job/parts/part-"{0..3}.ptp)
if "$pt" merge "${parts[0]}" "${parts[1]}" "${parts[3]}" -f "$S/work/c.png" 2>"$S/work/c1.err"; then fail "(c) merge accepted a set without part 2"; fi
grep -q "missing part 2" "$S/work/c1.err" || fail "(c) incomplete set: unexpected message: $(cat "$S/work/c1.err")"
if "$pt" merge "${parts[@]}" "${parts[1]}" -f "$S/work/c.png" 2>"$S/work/c2.err"; then fail "(c) merge accepted part 1 twice"; fi
grep -q "more than once" "$S/work/c2.err" || fail "(c) duplicated part: unexpected message: $(cat "$S/work/c2.err")"
[[ -f "$S/work/c.png" ]] && fail "(c) a refused merge left an image behind"
# An overlapping set: part 0 of an 8-way split of the same render beside part 0 of the 4-way one.
"$pt" "${scene_b[@]}" --part 0/8 --partial "$S/work/p0of8.ptp" >/dev/null
if "$pt" merge "$S/work/p0of8.ptp" "${parts[@]}" -f "$S/work/c.png" 2>"$S/work/c3.err"; then fail "(c) merge accepted overlapping parts"; fi
grep -q "overlapping parts" "$S/work/c3.err" || fail "(c) overlapping set: unexpected message: $(cat "$S/work/c3.err")"
# The merge job itself, with a part gone: it names it and the sbatch line.
rm "${parts[2]}"
mid2="$(sbatch --parsable "$S/work/b/job/merge.sh")"; mid2="${mid2%%;*}"
state="$(wait_job "$mid2" 60)"
[[ "$state" == FAILED ]] || fail "(c) the merge job with a part missing ended $state"
grep -q "sbatch --parsable --requeue --array=2 " "$S/work/b/job/logs/merge-$mid2.out" || fail "(c) the failed merge job did not give the re-render line: $(cat "$S/work/b/job/logs/merge-$mid2.out")"
log "(c) PASS: incomplete, duplicated and overlapping sets refused; the merge job lists part 2 and: $(grep -o 'sbatch --parsable --requeue --array=2 [^)]*' "$S/work/b/job/logs/merge-$mid2.out")"

# ---------------------------------------------------------------- (d)
# A part damaged on disk after its task finished (one bit of its pixel
# records), beside the part still missing from (c): the merge job names the
# damaged part, and the line it prints re-renders both; the merge that
# follows writes images byte-identical to the local render.
p1="$S/work/b/job/parts/part-1.ptp"
size="$(stat -c %s "$p1")"
byte="$(od -An -tu1 -j $((size - 1000)) -N1 "$p1" | tr -d ' ')"
printf "$(printf '\\%03o' $((byte ^ 4)))" | dd of="$p1" bs=1 seek=$((size - 1000)) conv=notrunc status=none
if "$pt" verify "${parts[0]}" "$p1" >"$S/work/d1.out" 2>"$S/work/d1.err"; then fail "(d) verify passed a damaged part"; fi
grep -q "part-1.ptp: records damaged (checksum mismatch)" "$S/work/d1.err" || fail "(d) verify did not name the damaged part: $(cat "$S/work/d1.err")"
grep -q "part-0.ptp: ok" "$S/work/d1.out" || fail "(d) verify did not pass the intact part: $(cat "$S/work/d1.out")"
rm -f "$S/work/b/img.png" "$S/work/b/img_rate.png" "$S/work/b/img.exr" "$S/work/b/var.exr"
mid3="$(sbatch --parsable "$S/work/b/job/merge.sh")"; mid3="${mid3%%;*}"
state="$(wait_job "$mid3" 60)"
[[ "$state" == FAILED ]] || fail "(d) the merge job with a damaged part ended $state"
out3="$S/work/b/job/logs/merge-$mid3.out"
grep -q "merge: part 1 is damaged: .*part-1.ptp: records damaged (checksum mismatch)" "$out3" || fail "(d) the merge job did not name the damaged part: $(cat "$out3")"
redo="$(grep -o 'JID=.*' "$out3")"
[[ "$redo" == *"--array=1,2 "* ]] || fail "(d) the re-render line does not cover parts 1 and 2: $redo"
resubmitted="$(eval "$redo")"
mid4="$(grep -o 'Submitted batch job [0-9]*' <<<"$resubmitted" | awk '{print $4}')"
[[ -n "$mid4" ]] || fail "(d) running the printed line submitted no merge job: $resubmitted"
state="$(wait_job "$mid4" 150)"
[[ "$state" == COMPLETED ]] || fail "(d) the merge job after the re-render ended $state: $(cat "$S/work/b/job/logs/merge-$mid4.out" 2>/dev/null)"
same_images "$S/work/local-b" "$S/work/b" || fail "(d) images merged after the re-render differ from the local render"
log "(d) PASS: part 1 damaged on disk: verify named it; the merge job named it and printed '$redo'; run as printed, it re-rendered parts 1 and 2 and the merge job $mid4 wrote images byte-identical to the local render"

# ---------------------------------------------------------------- teardown
stop_all
left="$(pgrep -a 'slurm|munge' || true)"
[[ -z "$left" ]] || fail "processes left running: $left"
log "teardown: every daemon stopped by its PID; no slurm or munge process left"
echo "slurm-e2e: 4 passed, 0 failed"
