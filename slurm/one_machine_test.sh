#!/usr/bin/env bash
# A real test on a real Slurm, on this one machine:
#   1. starts munged (as the munge user), slurmctld and slurmd in the foreground, with a
#      minimal slurm.conf, their state, sockets and logs under a temporary folder;
#   2. writes the batch scripts of a sharded reference with `stagelight slurm` and submits
#      them (a job array of SHARDS shards, then a merge job that depends on it), and compares
#      the merged image with one process rendering every pass: `cmp` must find them identical;
#   3. a sharded comparison (a plan of SHARDS tasks: PT and BDPT runs as shards, SPPM's whole,
#      the reference as shards) against the same comparison in one process: the references
#      must be identical (`cmp`) and so must every run's figures in results.csv but its
#      seconds (relMSE, RMSE, MAE, image means, samples, rays, photons);
#   4. stop and resume: 2 reference shards under a 1-minute time limit with
#      --signal=B:INT@55, so that Slurm signals them 5 to 35 s into each job (it checks time
#      limits every 30 s), with more work than that (RESUME_SECONDS at the rate measured
#      here): each keeps its passes, submits its next job (--dependency=singleton), which
#      resumes, until the shard is done; the merge job waits for the last of them, and the
#      merged image must equal the single render. Should this machine turn out faster than
#      measured, so that no job was stopped, it runs again with twice the work (at most
#      twice); every job is signalled before its limit, so none times out however slow;
#   5. whatever happens (success, a failed step, INT, TERM or HUP): cancels the jobs left in
#      its Slurm, stops every daemon it started by its PID (SIGTERM, SIGKILL after 15 s),
#      prints the tails of the daemons' and jobs' logs to stderr if it failed, and removes
#      its temporary folder (KEEP_TMP=1 keeps it, logs included).
#
#   slurm/one_machine_test.sh [STAGELIGHT]      (default target/release/stagelight)
#
# Needs the Debian packages slurmctld slurmd slurm-client munge, and root (SlurmUser=root).
# SHARDS (4), SPP (64), SIZE (64: the image is SIZE x SIZE), SCENE (cornell_box) and
# RESUME_SECONDS (45: the work of each stop-and-resume shard, in seconds) change the runs;
# SKIP_COMPARE=1 and SKIP_RESUME=1 leave out steps 3 and 4. Exit status 0 when every
# comparison holds.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
bin=$(realpath "${1:-$repo/target/release/stagelight}")
SHARDS=${SHARDS:-4}
SPP=${SPP:-64}
SIZE=${SIZE:-64}
SCENE=${SCENE:-cornell_box}
RESUME_SECONDS=${RESUME_SECONDS:-45}

for command in munged mungekey slurmctld slurmd sbatch squeue sinfo scontrol setpriv; do
    if ! command -v "$command" >/dev/null; then
        echo "one_machine_test: $command is missing (apt-get install slurmctld slurmd slurm-client munge)" >&2
        exit 2
    fi
done
[ "$(id -u)" -eq 0 ] || { echo "one_machine_test: run as root" >&2; exit 2; }
[ -x "$bin" ] || { echo "one_machine_test: no stagelight binary at $bin (cargo build --release)" >&2; exit 2; }

tmp=$(mktemp -d /tmp/stagelight-slurm.XXXXXX)
daemons=()
step="setting up"
failed_command=""
# Cancels what is left in this script's own Slurm (its controller, its jobs only), stops the
# daemons it started, only those, by the PIDs it got when it started them, shows the logs
# if it failed, and removes the temporary folder.
clean_up() {
    local status=$? pid waited f logs
    trap - EXIT ERR
    trap "" INT TERM HUP # (cleaning up is bounded: about a minute at most)
    set +e
    cd /
    if [ "$status" -ne 0 ]; then
        echo "one_machine_test: FAILED (exit status $status) in step: $step" >&2
        [ -z "$failed_command" ] || echo "one_machine_test: failing command: $failed_command" >&2
    fi
    if [ "${#daemons[@]}" -ge 2 ] && [ -n "$(timeout 10 squeue -h -o %i 2>/dev/null)" ]; then
        echo "cancelling the jobs left: $(timeout 10 squeue -h -o %i | tr '\n' ' ')" >&2
        # Again while any is left: a cancelled shard may have submitted its next job.
        for _ in $(seq 30); do
            timeout 10 scancel --user=root 2>/dev/null
            sleep 1
            [ -z "$(timeout 10 squeue -h -o %i 2>/dev/null)" ] && break
        done
    fi
    for pid in "${daemons[@]}"; do
        kill "$pid" 2>/dev/null
    done
    for pid in "${daemons[@]}"; do
        waited=0
        while kill -0 "$pid" 2>/dev/null && [ "$waited" -lt 150 ]; do
            sleep 0.1
            waited=$((waited + 1))
        done
        if kill -0 "$pid" 2>/dev/null; then
            echo "daemon $pid still running after 15 s: SIGKILL" >&2
            kill -KILL "$pid" 2>/dev/null
        fi
        wait "$pid" 2>/dev/null
    done
    echo "stopped daemons ${daemons[*]:-(none)}"
    if [ "$status" -ne 0 ]; then
        # A daemon's log file, or its stderr where it failed before it opened that file.
        logs=("$tmp"/log/munged.out "$tmp"/munge/munged.log)
        for f in slurmctld slurmd; do
            if [ -s "$tmp/log/$f.log" ]; then logs+=("$tmp/log/$f.log"); else logs+=("$tmp/log/$f.out"); fi
        done
        for f in "${logs[@]}" "$tmp"/work/*/logs/*; do
            [ -s "$f" ] || continue
            echo "--- ${f#"$tmp"/} (last 15 lines)" >&2
            tail -n 15 "$f" >&2
        done
    fi
    if [ "${KEEP_TMP:-0}" = 1 ]; then
        echo "kept $tmp (KEEP_TMP=1)"
    else
        rm -rf "$tmp"
        echo "removed $tmp"
    fi
    exit "$status"
}
trap clean_up EXIT
# A signal ends the script through its EXIT trap, so it cleans up as on failure.
trap 'exit 129' HUP
trap 'exit 130' INT
trap 'exit 143' TERM
set -E
trap 'failed_command="$BASH_COMMAND (line $LINENO)"' ERR
chmod 755 "$tmp"
mkdir -p "$tmp/munge" "$tmp/state" "$tmp/spool" "$tmp/log" "$tmp/work"

# --- munge: a fresh key, the daemon as the munge user, its socket in the temporary folder
step="1. starting munged"
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

step="1. starting slurmctld and slurmd"
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
step="2. the sharded reference (array + merge) against one process"
echo "== $SHARDS shards of a $SPP-spp reference of $SCENE at ${SIZE}x$SIZE"
"$bin" slurm --shards "$SHARDS" --cpus-per-task 1 -o job -- \
    reference scene.ron --spp "$SPP" -o merged.exr
t0=$(date +%s.%N)
sh job/submit.sh
wait_for_queue 600
t1=$(date +%s.%N)
cat job/logs/merge.out
[ -f merged.exr ] || { echo "the merge job wrote no merged.exr (its log above)" >&2; exit 1; }
echo "array + merge: $(elapsed "$t0" "$t1") s wall"
t0=$(date +%s.%N)
"$bin" reference scene.ron --spp "$SPP" -o single.exr --quiet
t1=$(date +%s.%N)
echo "single process: $(elapsed "$t0" "$t1") s wall"
echo "\$ cmp single.exr merged.exr"
cmp single.exr merged.exr
echo "cmp: identical"

# --- 3. a sharded comparison against one process
if [ "${SKIP_COMPARE:-0}" != 1 ]; then
    step="3. the sharded comparison against one process"
    # shellcheck disable=SC2054 # (pt,bdpt,sppm is one argument)
    compare_args=(compare scene.ron --integrators pt,bdpt,sppm --budgets 16,64 --budget-unit spp
        --reference-spp "$SPP" --photons-per-pass 5000)
    echo "== a comparison of pt, bdpt and sppm at 16 and 64 spp as a plan of $SHARDS tasks"
    "$bin" slurm --shards "$SHARDS" --cpus-per-task 1 -o cjob -- "${compare_args[@]}" -o sharded
    t0=$(date +%s.%N)
    sh cjob/submit.sh
    wait_for_queue 600
    t1=$(date +%s.%N)
    tail -n 3 cjob/logs/merge.out
    echo "task array + report: $(elapsed "$t0" "$t1") s wall"
    t0=$(date +%s.%N)
    "$bin" "${compare_args[@]}" -o one --quiet >/dev/null
    t1=$(date +%s.%N)
    echo "one process: $(elapsed "$t0" "$t1") s wall"
    echo "\$ cmp one/reference.exr sharded/reference.exr"
    cmp one/reference.exr sharded/reference.exr
    # Every column of results.csv but wall_s, cpu_s and efficiency (4, 5, 14).
    cut -d, -f1-3,6-13,15-17 one/results.csv >one.figures
    cut -d, -f1-3,6-13,15-17 sharded/results.csv >sharded.figures
    echo "\$ cmp one.figures sharded.figures   ($(($(wc -l <one.figures) - 1)) runs)"
    cmp one.figures sharded.figures
    echo "cmp: identical"
fi

# --- 4. stop and resume under a time limit
if [ "${SKIP_RESUME:-0}" != 1 ]; then
    step="4. stop and resume under a time limit"
    # Passes per second on one thread, from a short render, size each shard's work.
    "$bin" reference scene.ron --time 3 --threads 1 -o rate.exr --quiet >rate.txt
    passes=$(sed -n 's/.* at \([0-9]*\) spp (\([0-9.]*\) s of rendering).*/\1 \2/p' rate.txt)
    work=$RESUME_SECONDS
    for attempt in 1 2 3; do
        spp=$(echo "$passes" | awk -v s="$work" '{ printf "%d", 2 * s * $1 / $2 }')
        echo "== stop and resume: 2 shards of a $spp-spp reference, each ~$work s of work, time limit 1 min"
        rm -rf resume resumed.exr resumed.exr.checkpoint resumed.png
        "$bin" slurm --shards 2 --cpus-per-task 1 --time-limit 1 --signal-seconds 55 -o resume -- \
            reference scene.ron --spp "$spp" --checkpoint-every 5 -o resumed.exr
        t0=$(date +%s.%N)
        sh resume/submit.sh
        wait_for_queue 1200
        t1=$(date +%s.%N)
        echo "array + next jobs + merge: $(elapsed "$t0" "$t1") s wall"
        grep -h "exit\|resumed\|made\|continues" resume/logs/shard-*.out || true
        cat resume/logs/merge.out
        [ -f resumed.exr ] || { echo "the merge job wrote no resumed.exr (its log above)" >&2; exit 1; }
        grep -q "continues in job" resume/logs/shard-*.out && break
        if [ "$attempt" -eq 3 ]; then
            echo "no shard was stopped by its time limit, even with $work s of work" >&2
            exit 1
        fi
        work=$((2 * work))
        echo "no shard was stopped by its time limit (this machine is faster than measured): again with $work s of work"
    done
    "$bin" reference scene.ron --spp "$spp" -o resumed_single.exr --quiet
    echo "\$ cmp resumed_single.exr resumed.exr"
    cmp resumed_single.exr resumed.exr
    echo "cmp: identical"
fi
step="done"
echo "one_machine_test: all comparisons identical"
