#!/usr/bin/env bash
# Run a campaign as a Slurm array job on a one-node cluster started here,
# merge the shards, and compare the merged folder with one run on this
# machine: every file but the run cache (.cache/) and the timings
# (run.jsonl) must be byte-identical.
#
#     scripts/slurm-shards.sh SERVOID MANIFEST SHARDS WORKDIR
#
# SERVOID is the servoid binary, MANIFEST a campaign manifest, SHARDS the
# number of array tasks, WORKDIR a folder that must not exist yet: it gets
# shard-<i>/ (one per task), merged/, single/ and the cluster's own files
# (cluster/: slurm.conf, the daemons' logs and state, the tasks' output).
#
# What it needs: Debian's slurm-wlm and munge (`apt-get install -y
# slurm-wlm munge`), and root, as slurmd starts jobs as their user.
# It starts munged (unless one already answers), then slurmctld and slurmd
# on their own ports with a slurm.conf under WORKDIR (the machine's
# /etc/slurm is not touched), submits `servoid run --shard i/n` as
# `sbatch --wait --array=0-(n-1)`, and stops every daemon it started on its
# way out, whatever happens. Exit 0 when the merged folder equals the
# single run, 1 when it differs or a step fails, 2 when something it needs
# is missing.
set -euo pipefail

if [[ $# -ne 4 ]]; then
    echo "usage: $0 SERVOID MANIFEST SHARDS WORKDIR" >&2
    exit 2
fi
servoid=$(realpath "$1")
manifest=$(realpath "$2")
shards=$3
work=$4

for cmd in munged munge slurmctld slurmd sbatch sinfo; do
    if ! command -v "$cmd" >/dev/null; then
        echo "slurm-shards: $cmd is missing; install it with: apt-get install -y slurm-wlm munge" >&2
        exit 2
    fi
done
if [[ $(id -u) -ne 0 ]]; then
    echo "slurm-shards: run it as root (slurmd starts the jobs as their user)" >&2
    exit 2
fi
if ! [[ $shards =~ ^[1-9][0-9]*$ ]]; then
    echo "slurm-shards: SHARDS must be a positive number, not '$shards'" >&2
    exit 2
fi
if [[ -e $work ]]; then
    echo "slurm-shards: $work exists already; give a new folder" >&2
    exit 2
fi
mkdir -p "$work/cluster"
work=$(realpath "$work")
cluster=$work/cluster

started_munge=""
cleanup() {
    local code=$?
    for daemon in slurmd slurmctld; do
        if [[ -f $cluster/$daemon.pid ]]; then
            kill "$(cat "$cluster/$daemon.pid")" 2>/dev/null || true
        fi
    done
    if [[ -n $started_munge && -f $cluster/munged.pid ]]; then
        kill "$(cat "$cluster/munged.pid")" 2>/dev/null || true
    fi
    exit "$code"
}
trap cleanup EXIT
trap 'exit 1' INT TERM

say() { echo "== slurm-shards: $*"; }

# munge authenticates slurmctld, slurmd and the clients to each other. The
# package creates the key; a machine without one gets a fresh key.
if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    if [[ ! -s /etc/munge/munge.key ]]; then
        say "creating a munge key"
        mkdir -p /etc/munge
        dd if=/dev/urandom bs=1 count=1024 of=/etc/munge/munge.key status=none
        chmod 400 /etc/munge/munge.key
    fi
    chown -R munge:munge /etc/munge 2>/dev/null || true
    mkdir -p /run/munge /var/log/munge /var/lib/munge
    chown munge:munge /run/munge /var/log/munge /var/lib/munge 2>/dev/null || true
    say "starting munged"
    munged --force --pid-file="$cluster/munged.pid"
    started_munge=yes
    for _ in $(seq 50); do
        munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break
        sleep 0.1
    done
fi
munge -n | unmunge | grep -q 'STATUS: *Success' || {
    echo "slurm-shards: munge does not authenticate (munge -n | unmunge)" >&2
    exit 1
}

# A one-node cluster: this machine's cores, a GiB less memory than it has
# (slurmd refuses a node that claims more than it finds), ports away from a
# cluster the machine may run already.
host=$(hostname -s)
mem_mib=$(($(free -m | awk '/^Mem:/ {print $2}') - 1024))
user=$(id -un)
mkdir -p "$cluster/state" "$cluster/spool" "$cluster/out"
export SLURM_CONF=$cluster/slurm.conf
cat >"$SLURM_CONF" <<EOF
ClusterName=servoid-ci
SlurmctldHost=$host
SlurmctldPort=${SERVOID_SLURMCTLD_PORT:-16817}
SlurmdPort=${SERVOID_SLURMD_PORT:-16818}
SlurmUser=$user
SlurmdUser=$user
AuthType=auth/munge
CredType=cred/munge
StateSaveLocation=$cluster/state
SlurmdSpoolDir=$cluster/spool
SlurmctldPidFile=$cluster/slurmctld.pid
SlurmdPidFile=$cluster/slurmd.pid
SlurmctldLogFile=$cluster/slurmctld.log
SlurmdLogFile=$cluster/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
MpiDefault=none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
SlurmdTimeout=60
NodeName=$host CPUs=$(nproc) RealMemory=$mem_mib State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF

say "starting slurmctld and slurmd ($(nproc) CPUs, $mem_mib MiB)"
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF"
ready=""
for _ in $(seq 120); do
    state=$(sinfo -h -n "$host" -o '%t' 2>/dev/null || true)
    if [[ $state == idle* ]]; then
        ready=yes
        break
    fi
    sleep 0.5
done
if [[ -z $ready ]]; then
    echo "slurm-shards: the node is not idle after 60 s (sinfo: '${state:-nothing}'); see $cluster/slurmctld.log and slurmd.log" >&2
    exit 1
fi
sinfo

# One task per share: servoid run --shard i/n into shard-i (0-based, as
# SLURM_ARRAY_TASK_ID). --jobs 1: each task is one core, and Slurm shares
# out the cores.
cat >"$cluster/task.sh" <<EOF
#!/usr/bin/env bash
set -euo pipefail
i=\$SLURM_ARRAY_TASK_ID
exec "$servoid" run "$manifest" --shard "\$i/$shards" --out "$work/shard-\$i" --jobs 1 --quiet
EOF
chmod +x "$cluster/task.sh"

say "sbatch --wait --array=0-$((shards - 1))"
if ! sbatch --wait --array="0-$((shards - 1))" --cpus-per-task=1 \
    --job-name=servoid-shards --chdir="$work" \
    --output="$cluster/out/task-%a.out" --error="$cluster/out/task-%a.err" \
    "$cluster/task.sh"; then
    echo "slurm-shards: the array job failed; the tasks' stderr:" >&2
    tail -n 5 "$cluster"/out/task-*.err >&2 || true
    exit 1
fi
for ((i = 0; i < shards; i++)); do
    if [[ ! -f $work/shard-$i/shard.json ]]; then
        echo "slurm-shards: task $i wrote no shard-$i/shard.json" >&2
        exit 1
    fi
done

say "merging ${shards} shards"
shard_dirs=()
for ((i = 0; i < shards; i++)); do shard_dirs+=("$work/shard-$i"); done
"$servoid" merge "${shard_dirs[@]}" --out "$work/merged" --quiet

say "one run on this machine"
"$servoid" run "$manifest" --out "$work/single" --quiet

say "comparing merged/ with single/ (all but .cache/ and run.jsonl)"
if diff -r --exclude=.cache --exclude=run.jsonl "$work/single" "$work/merged"; then
    files=$(cd "$work/single" && find . -path ./.cache -prune -o -type f ! -name run.jsonl -print | wc -l)
    say "identical: $files files"
else
    echo "slurm-shards: the merged shards differ from one run" >&2
    exit 1
fi
