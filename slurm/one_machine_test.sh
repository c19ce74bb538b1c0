#!/usr/bin/env bash
# A real test on a real Slurm, on this one machine:
#   1. starts munged (as the munge user), slurmctld and slurmd in the foreground, with a
#      minimal slurm.conf, their state, sockets and logs under a temporary folder;
#   2. writes the batch scripts of a sharded reference with `stagelight slurm` and submits
#      them (a job array of SHARDS shards, then a merge job that depends on it), and compares
#      the merged image with one process rendering every pass: `cmp` must find them identical;
#   3. stop and resume: shards under a 1-minute time limit with --signal=B:INT@55, so that
#      Slurm signals them 5 to 35 s into their run (it checks time limits every 30 s), before
#      their 40 s of work is done: they keep their passes, requeue (Slurm holds a requeued
#      job for 2 minutes) and resume; the merged image must equal the single render;
#   4. stops every daemon it started, by its PID (also on failure).
#
#   slurm/one_machine_test.sh [STAGELIGHT]      (default target/release/stagelight)
#
# Needs the Debian packages slurmctld slurmd slurm-client munge, and root (SlurmUser=root).
# SHARDS (4), SPP (64), SIZE (64: the image is SIZE x SIZE), SCENE (cornell_box) and
# RESUME_SECONDS (40: the work of each stop-and-resume shard, in seconds) change the runs;
# SKIP_RESUME=1 leaves out step 3. Exit status 0 when every comparison holds.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
bin=$(realpath "${1:-$repo/target/release/stagelight}")
SHARDS=${SHARDS:-4}
SPP=${SPP:-64}
SIZE=${SIZE:-64}
SCENE=${SCENE:-cornell_box}
RESUME_SECONDS=${RESUME_SECONDS:-40}

for command in munged mungekey slurmctld slurmd sbatch squeue sinfo scontrol setpriv; do
    if ! command -v "$command" >/dev/null; then
        echo "one_machine_test: $command is missing (apt-get install slurmctld slurmd slurm-client munge)" >&2
        exit 2
    fi
done
[ "$(id -u)" -eq 0 ] || { echo "one_machine_test: run as root" >&2; exit 2; }
[ -x "$bin" ] || { echo "one_machine_test: no stagelight binary at $bin (cargo build --release)" >&2; exit 2; }

tmp=$(mktemp -d /tmp/stagelight-slurm.XXXXXX)
chmod 755 "$tmp"
mkdir -p "$tmp/munge" "$tmp/state" "$tmp/spool" "$tmp/log" "$tmp/work"
daemons=()
stop_daemons() {
    # Only the daemons this script started, by the PIDs it got when it started them.
    for pid in "${daemons[@]}"; do
        kill "$pid" 2>/dev/null || true
    done
    for pid in "${daemons[@]}"; do
        wait "$pid" 2>/dev/null || true
    done
    echo "stopped daemons ${daemons[*]:-}; logs in $tmp/log"
}
trap stop_daemons EXIT

# --- munge: a fresh key, the daemon as the munge user, its socket in the temporary folder
chown munge: "$tmp/munge"
chmod 700 "$tmp/munge"
mungekey --create --keyfile="$tmp/munge/munge.key"
chown munge: "$tmp/munge/munge.key"
chmod 400 "$tmp/munge/munge.key"
socket=$tmp/munge/munge.socket
setpriv --reuid=munge --regid=munge --init-groups \
    munged --foreground --force --socket="$socket" --key-file="$tmp/munge/munge.key" \
    --pid-file="$tmp/munge/munged.pid" --log-file="$tmp/munge/munged.log" \
    --seed-file="$tmp/munge/munged.seed" >"$tmp/log/munged.out" 2>&1 &
daemons+=($!)
for _ in $(seq 100); do [ -S "$socket" ] && break; sleep 0.1; done
[ -S "$socket" ] || { echo "munged did not start: $(cat "$tmp/munge/munged.log")" >&2; exit 1; }

# --- slurm.conf: this host as controller and only node, no accounting, no cgroups
host=$(hostname -s)
node=$(slurmd -C | head -n 1)
cat >"$tmp/slurm.conf" <<EOF
ClusterName=stagelight
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$socket
CredType=cred/munge
SlurmctldPort=16817
SlurmdPort=16818
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmctldLogFile=$tmp/log/slurmctld.log
SlurmdLogFile=$tmp/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MinJobAge=600
KillWait=10
$node State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF=$tmp/slurm.conf

# Seconds from $1 to $2 (default now), both `date +%s.%N`.
elapsed() { awk -v a="$1" -v b="${2:-$(date +%s.%N)}" 'BEGIN { printf "%.1f", b - a }'; }

started=$(date +%s.%N)
slurmctld -D -i >"$tmp/log/slurmctld.out" 2>&1 &
daemons+=($!)
slurmd -D >"$tmp/log/slurmd.out" 2>&1 &
daemons+=($!)
for _ in $(seq 300); do
    sinfo -h -o %T 2>/dev/null | grep -qx idle && break
    sleep 0.2
done
sinfo -h -o %T | grep -qx idle || { echo "the node did not come up idle:"; sinfo; exit 1; }
echo "slurm: node $host idle after $(elapsed "$started") s (daemons ${daemons[*]})"

# Waits until no job is left in the queue (at most $1 seconds).
wait_for_queue() {
    local limit=$1 waited=0
    while [ -n "$(squeue -h -o %i)" ]; do
        sleep 1
        waited=$((waited + 1))
        if [ "$waited" -ge "$limit" ]; then
            echo "jobs still queued after $limit s:"; squeue; return 1
        fi
    done
}

cd "$tmp/work"
# The scene at SIZE x SIZE.
sed "0,/camera: (/s//camera: (\n        width: $SIZE,\n        height: $SIZE,/" \
    "$repo/scenes/$SCENE.ron" >scene.ron

# --- 2. a sharded reference against one process
echo "== $SHARDS shards of a $SPP-spp reference of $SCENE at ${SIZE}x$SIZE"
"$bin" slurm --shards "$SHARDS" --cpus-per-task 1 -o job -- \
    reference scene.ron --spp "$SPP" -o merged.exr
t0=$(date +%s.%N)
sh job/submit.sh
wait_for_queue 600
t1=$(date +%s.%N)
cat job/logs/merge.out
echo "array + merge: $(elapsed "$t0" "$t1") s wall"
t0=$(date +%s.%N)
"$bin" reference scene.ron --spp "$SPP" -o single.exr --quiet
t1=$(date +%s.%N)
echo "single process: $(elapsed "$t0" "$t1") s wall"
echo "\$ cmp single.exr merged.exr"
cmp single.exr merged.exr
echo "cmp: identical"

# --- 3. stop and resume under a time limit
if [ "${SKIP_RESUME:-0}" != 1 ]; then
    # Passes per second on one thread, from a short render, make each shard about
    # RESUME_SECONDS of work: more than its 1-minute time limit allows.
    "$bin" reference scene.ron --time 3 --threads 1 -o rate.exr --quiet >rate.txt
    passes=$(sed -n 's/.* at \([0-9]*\) spp (\([0-9.]*\) s of rendering).*/\1 \2/p' rate.txt)
    spp=$(echo "$passes" | awk -v s="$RESUME_SECONDS" '{ printf "%d", 2 * s * $1 / $2 }')
    echo "== stop and resume: 2 shards of a $spp-spp reference, each ~$RESUME_SECONDS s of work, time limit 1 min"
    "$bin" slurm --shards 2 --cpus-per-task 1 --time-limit 1 --signal-seconds 55 -o resume -- \
        reference scene.ron --spp "$spp" --checkpoint-every 5 -o resumed.exr
    t0=$(date +%s.%N)
    sh resume/submit.sh
    wait_for_queue 1200
    t1=$(date +%s.%N)
    echo "array + merge with requeues: $(elapsed "$t0" "$t1") s wall"
    grep -h "exit\|resumed\|made" resume/logs/shard-*.out || true
    cat resume/logs/merge.out
    if ! grep -q "exit 130" resume/logs/shard-*.out; then
        echo "no shard was stopped by its time limit: raise RESUME_SECONDS" >&2
        exit 1
    fi
    "$bin" reference scene.ron --spp "$spp" -o resumed_single.exr --quiet
    echo "\$ cmp resumed_single.exr resumed.exr"
    cmp resumed_single.exr resumed.exr
    echo "cmp: identical"
fi
echo "one_machine_test: all comparisons identical"
