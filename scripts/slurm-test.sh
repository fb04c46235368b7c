#!/usr/bin/env bash
# Slurm for real: munged, slurmctld and slurmd on localhost (one node, 2 CPUs), the shards of a
# generated ~200-group scan submitted as a job array with a dependent merge, the merged WAV
# compared byte for byte with the one-process WAV, then the daemons shut down. Installs
# Debian's slurm-wlm and munge when they are missing (needs root). Fails on any mismatch.
#   bash scripts/slurm-test.sh            # uses target/debug/groovescope (built if missing)
#   GROOVESCOPE=/path/to/groovescope bash scripts/slurm-test.sh
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    $SUDO apt-get install -y -qq slurm-wlm munge >/dev/null
fi
if [ -z "${GROOVESCOPE:-}" ]; then
    cargo build --locked --quiet
    GROOVESCOPE="$PWD/target/debug/groovescope"
fi
export GROOVESCOPE
SHARDS=4
work=$(mktemp -d /tmp/groovescope-slurm.XXXXXX)
node=$(hostname -s)
conf="$work/slurm.conf"
munge_pid=""

shutdown() {
    local status=$?
    set +e
    # The daemons' pids before asking them to stop: slurmctld removes its pid file as it begins
    # to shut down, so waiting on the file could stop waiting on a daemon still running.
    local pids=() pidfile pid
    for pidfile in "$work/slurmctld.pid" "$work/slurmd.pid"; do
        [ -f "$pidfile" ] && pids+=("$(cat "$pidfile")")
    done
    if [ -f "$conf" ]; then SLURM_CONF="$conf" scontrol shutdown >/dev/null 2>&1; fi
    for pid in "${pids[@]}"; do
        for _ in $(seq 50); do
            kill -0 "$pid" 2>/dev/null || break
            sleep 0.1
        done
        kill "$pid" 2>/dev/null
    done
    if [ -n "$munge_pid" ]; then kill "$munge_pid" 2>/dev/null; fi
    # Only now, with the daemons gone (a later run reuses their ports); a failed run keeps its
    # logs.
    if [ "$status" = 0 ]; then rm -rf "$work"; else echo "slurm-test: logs kept in $work" >&2; fi
}
trap shutdown EXIT

# --- munge: a key of our own and a daemon on its own socket -----------------------------------
mkdir -p "$work/munge"
dd if=/dev/urandom of="$work/munge/munge.key" bs=1024 count=1 status=none
chmod 700 "$work/munge"
chmod 400 "$work/munge/munge.key"
socket="$work/munge/munge.socket"
munged --force --key-file="$work/munge/munge.key" --socket="$socket" \
    --pid-file="$work/munge/munged.pid" --log-file="$work/munge/munged.log" \
    --seed-file="$work/munge/munged.seed"
munge_pid=$(cat "$work/munge/munged.pid")

# --- Slurm: one node with 2 CPUs, no cgroups (containers), no accounting ------------------------
mkdir -p "$work/state" "$work/spool"
cat >"$conf" <<EOF
ClusterName=groovescope-ci
SlurmctldHost=$node(127.0.0.1)
SlurmctldPort=16817
SlurmdPort=16818
AuthType=auth/munge
AuthInfo=socket=$socket
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
MpiDefault=none
ReturnToService=2
MinJobAge=600
NodeName=$node NodeAddr=127.0.0.1 CPUs=2 RealMemory=4000 State=UNKNOWN
PartitionName=ci Nodes=$node Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF="$conf"
slurmctld -f "$conf"
slurmd -f "$conf" -N "$node"
for i in $(seq 60); do
    state=$(sinfo -h -N -o '%T' 2>/dev/null | head -1 || true)
    [ "$state" = idle ] && break
    if [ "$i" = 60 ]; then
        echo "slurm-test: the node did not come up (state '$state')" >&2
        tail -20 "$work/slurmctld.log" "$work/slurmd.log" >&2
        exit 1
    fi
    sleep 1
done
echo "slurm-test: slurmctld and slurmd up on $node ($(sinfo -h -o '%C' | cut -d/ -f4) CPUs)"

# --- the scan and the one-process reference ------------------------------------------------------
"$GROOVESCOPE" synth --preset dual-focus --config "scripts/small-side-synth.toml" --tone 1000 \
    --duration 0.033 --max-groups 200 --out "$work/scan" --quiet
groups=$(find "$work/scan" -mindepth 1 -maxdepth 1 -type d | wc -l)
t0=$(date +%s.%N)
"$GROOVESCOPE" reconstruct "$work/scan" --out "$work/one.wav" --quiet
t1=$(date +%s.%N)

# --- the job array and the dependent merge --------------------------------------------------------
"$GROOVESCOPE" plan "$work/scan" --shards "$SHARDS" --out "$work/plan.json" --parts "$work/parts" \
    --slurm >"$work/plan.txt"
cat "$work/plan.txt"
t2=$(date +%s.%N)
array=$(sbatch --parsable --chdir="$work" --output="$work/shard-%a.log" --cpus-per-task=1 \
    --array=0-$((SHARDS - 1)) scripts/slurm/reconstruct-side.sbatch \
    "$work/scan" "$work/plan.json" "$work/parts")
merge=$(sbatch --parsable --chdir="$work" --output="$work/merge.log" \
    --dependency=afterok:"$array" scripts/slurm/merge-side.sbatch "$work/parts" "$work/side.wav")
echo "slurm-test: submitted array job $array ($SHARDS shards) and merge job $merge"
merge_state=""
for _ in $(seq 600); do
    merge_state=$(scontrol show job "$merge" 2>/dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p')
    case "$merge_state" in COMPLETED | FAILED | CANCELLED | TIMEOUT | NODE_FAIL | OUT_OF_MEMORY) break ;; esac
    sleep 0.5
done
t3=$(date +%s.%N)
if [ "$merge_state" != COMPLETED ]; then
    echo "slurm-test: the merge job ended $merge_state" >&2
    tail -n 20 "$work"/*.log >&2
    exit 1
fi
for k in $(seq 0 $((SHARDS - 1))); do
    test -s "$work/parts/part-$k/part.gsp"
done
if ! cmp "$work/one.wav" "$work/side.wav"; then
    echo "slurm-test: FAILED: the merged WAV differs from the one-process WAV" >&2
    exit 1
fi
one=$(echo "$t1 - $t0" | bc)
slurm=$(echo "$t3 - $t2" | bc)
echo "slurm-test: passed: $groups groups, $SHARDS shards on 2 CPUs; merged WAV byte-identical to the one-process WAV ($(wc -c <"$work/side.wav") bytes)"
printf 'slurm-test: wall time: one process %.1f s, Slurm array + merge (submit to merged WAV) %.1f s\n' "$one" "$slurm"
