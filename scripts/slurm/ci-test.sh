#!/bin/bash
# The Slurm recipe of docs/cluster.md on a real, single-node Slurm: installs slurm-wlm
# and munge from Debian's packages if needed (as root), starts munged, slurmctld and
# slurmd with a configuration of its own (in a temporary folder; nothing in /etc/slurm
# changes), submits the quick Fig. 3 protocol as a job array and the merge
# as a dependent job (2 tasks: the quick protocol has 2 poses, and a shard with no
# run is an error), checks that the merged rows equal a single run's (every column
# but the wall time) and that the merge says it is complete, then stops the daemons it
# started. Usage: scripts/slurm/ci-test.sh BENCH_CONV_BINARY
set -euo pipefail
bin="$(realpath "${1:?usage: $0 path/to/bench-conv}")"
root="$(cd "$(dirname "$0")/../.." && pwd)"
work="$(mktemp -d /tmp/pgm-slurm.XXXXXX)"
chmod 755 "$work"

if ! command -v sbatch > /dev/null || ! command -v munged > /dev/null; then
    echo "installing slurm-wlm and munge"
    sudo=()
    if [ "$(id -u)" -ne 0 ]; then sudo=(sudo); fi
    export DEBIAN_FRONTEND=noninteractive
    timeout 300 "${sudo[@]}" apt-get update -q > "$work/apt.log" 2>&1
    timeout 300 "${sudo[@]}" apt-get install -y -q slurm-wlm munge >> "$work/apt.log" 2>&1 || { cat "$work/apt.log"; exit 1; }
fi

started=()
stop() {
    if [ -n "${SLURM_CONF:-}" ]; then
        scancel --full --user=root > /dev/null 2>&1 || true
        sleep 1
        scontrol shutdown > /dev/null 2>&1 || true
    fi
    sleep 1
    for pid in "${started[@]}"; do kill "$pid" 2> /dev/null || true; done
    if [ -n "${munge_pid:-}" ]; then kill "$munge_pid" 2> /dev/null || true; fi
}
trap stop EXIT

# munge: its own key and socket, in the temporary folder.
mkdir -p "$work/munge"
dd if=/dev/urandom of="$work/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$work/munge/munge.key"
munged --force --key-file="$work/munge/munge.key" --socket="$work/munge/socket" \
    --pid-file="$work/munge/munged.pid" --log-file="$work/munge/munged.log" \
    --seed-file="$work/munge/seed"
munge_pid="$(cat "$work/munge/munged.pid")"

host="$(hostname -s)"
cpus="$(nproc)"
mkdir -p "$work/spool" "$work/state"
cat > "$work/slurm.conf" <<CONF
ClusterName=pgm-ci
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$work/munge/socket
CredType=cred/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
ReturnToService=2
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmdSpoolDir=$work/spool
StateSaveLocation=$work/state
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
NodeName=$host CPUs=$cpus State=UNKNOWN
PartitionName=ci Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$work/slurm.conf"
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF"
sleep 1
started+=("$(cat "$work/slurmctld.pid" 2> /dev/null || true)" "$(cat "$work/slurmd.pid" 2> /dev/null || true)")
for _ in $(seq 60); do
    if sinfo -h -o %T 2> /dev/null | grep -qE '^(idle|mixed|allocated)'; then break; fi
    sleep 1
done
sinfo

# The recipe: one shard per array task, then the merge once they all succeeded.
cd "$root"
results="$work/results"
mkdir -p "$results"
export PROTOCOL="$root/fixtures/protocol-fig3-quick.toml" RESULTS="$results" BENCH_CONV="$bin"
array=$(sbatch --parsable --array=0-1 --cpus-per-task=1 --export=ALL \
    --output="$work/array-%A_%a.out" scripts/slurm/protocol-array.sbatch)
merge=$(sbatch --parsable --dependency=afterok:"$array" --kill-on-invalid-dep=yes --export=ALL \
    --output="$work/merge-%j.out" \
    --wrap "\"$bin\" merge \"$results\"/shard-*/runs.csv --out \"$results/merged\"")
echo "submitted array $array and merge $merge"
for _ in $(seq 300); do
    if [ -z "$(squeue -h -j "$array,$merge" 2> /dev/null)" ]; then break; fi
    sleep 1
done
cat "$work"/array-*.out "$work"/merge-*.out || true
test -f "$results/merged/runs.csv" || { echo "no merged runs.csv"; cat "$work/slurmctld.log"; exit 1; }
test ! -e "$results/merged/INCOMPLETE" || { echo "merge left INCOMPLETE"; exit 1; }
grep -q "^Complete: all" "$results/merged/summary.md" || { echo "merge not complete"; cat "$results/merged/summary.md"; exit 1; }

# The same protocol in one process: the rows must be equal but for the wall time.
"$bin" run "$PROTOCOL" --out "$work/single" > /dev/null
strip() { python3 -c '
import csv, sys
rows = list(csv.reader(open(sys.argv[1])))
t = rows[0].index("wall_time_s")
for r in rows: print(",".join(v for i, v in enumerate(r) if i != t))' "$1"; }
strip "$work/single/runs.csv" > "$work/single.rows"
strip "$results/merged/runs.csv" > "$work/merged.rows"
if [ "$(wc -l < "$work/single.rows")" -lt 2 ] || ! diff "$work/single.rows" "$work/merged.rows"; then
    echo "the Slurm merge differs from the single run"
    exit 1
fi
echo "slurm: the 2-task array merged equals the single run ($(($(wc -l < "$results/merged/runs.csv") - 1)) runs)"
