#!/usr/bin/env bash
# A single-node Slurm cluster in a folder of its own, from Debian's packages
# (munge, slurmctld, slurmd, slurm-client): what the Slurm executor's test runs
# against, and a way to try `collidoscope serve --executor slurm` on one machine.
#
#   scripts/slurm-local.sh start DIR   # prints the environment to use it (SLURM_CONF=...)
#   scripts/slurm-local.sh stop DIR
#
# Sandbox-friendly: no systemd, no cgroups (proctrack/linuxproc, task/none),
# every spool, state, socket and log under DIR, ports chosen free, the daemons
# run as the calling user. Memory limits are enforced by the job accounting
# poller (jobacct_gather/linux with OverMemoryKill), so a job over its --mem
# ends OUT_OF_MEMORY as on a real cluster. Exit 77 (skip) when the packages are
# missing or the daemons cannot start here; the reason is printed.
set -euo pipefail

cmd=${1:-}
dir=${2:-}
if [ -z "$cmd" ] || [ -z "$dir" ]; then
  echo "usage: $0 start|stop DIR" >&2
  exit 2
fi

stop_cluster() {
  for name in slurmd slurmctld munged; do
    pidfile="$dir/$name.pid"
    [ -f "$pidfile" ] || continue
    pid=$(cat "$pidfile" 2>/dev/null || true)
    [ -n "$pid" ] && kill "$pid" 2>/dev/null || true
  done
  # Give them a moment, then make sure (a test must not leave daemons behind).
  for _ in $(seq 50); do
    alive=0
    for name in slurmd slurmctld munged; do
      pid=$(cat "$dir/$name.pid" 2>/dev/null || true)
      [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null && alive=1
    done
    [ $alive = 0 ] && break
    sleep 0.1
  done
  for name in slurmd slurmctld munged; do
    pid=$(cat "$dir/$name.pid" 2>/dev/null || true)
    [ -n "$pid" ] && kill -9 "$pid" 2>/dev/null || true
    rm -f "$dir/$name.pid"
  done
}

if [ "$cmd" = stop ]; then
  stop_cluster
  exit 0
fi
[ "$cmd" = start ] || { echo "usage: $0 start|stop DIR" >&2; exit 2; }

skip() {
  echo "slurm-local: cannot start Slurm here: $*" >&2
  stop_cluster
  exit 77
}

for tool in munged mungekey slurmctld slurmd sbatch squeue scontrol scancel; do
  command -v "$tool" >/dev/null 2>&1 || [ -x "/usr/sbin/$tool" ] ||
    skip "$tool is not installed (scripts/install-deps.sh installs munge, slurmctld, slurmd, slurm-client)"
done
export PATH="$PATH:/usr/sbin"

mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
# munged refuses a socket folder others may write to and a key others may read,
# and wants the socket's folder searchable by all.
chmod 0755 "$dir"
mkdir -p "$dir/munge" "$dir/ctld" "$dir/spool"
chmod 0755 "$dir/munge"

# Three free TCP ports on loopback (controller, node daemon, srun's range start).
read -r ctld_port slurmd_port < <(python3 - <<'EOF'
import socket
socks = []
for _ in range(2):
    s = socket.socket(); s.bind(("127.0.0.1", 0)); socks.append(s)
print(*[s.getsockname()[1] for s in socks])
EOF
)

user=$(id -un)
node=collido-node
host=$(hostname -s)
cpus=$(nproc)
# The node offers what this machine has, less a little for the system.
mem_mb=$(awk '/MemTotal/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)

mungekey --create --force --keyfile "$dir/munge/munge.key" >/dev/null 2>&1 ||
  skip "mungekey could not make a key"
chmod 0600 "$dir/munge/munge.key"
munged --force --socket "$dir/munge/munge.sock" --key-file "$dir/munge/munge.key" \
  --pid-file "$dir/munged.pid" --log-file "$dir/munged.log" --seed-file "$dir/munge/seed" \
  >"$dir/munged.out" 2>&1 || skip "munged did not start: $(tail -3 "$dir/munged.out" "$dir/munged.log" 2>/dev/null)"

cat >"$dir/slurm.conf" <<EOF
# A single-node cluster for collidoscope's tests (scripts/slurm-local.sh).
ClusterName=collido
SlurmctldHost=$host(127.0.0.1)
SlurmUser=$user
SlurmdUser=$user
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge/munge.sock
StateSaveLocation=$dir/ctld
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/linux
JobAcctGatherFrequency=task=1
JobAcctGatherParams=OverMemoryKill
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
SlurmdParameters=config_overrides
ReturnToService=2
MpiDefault=none
# Finished jobs stay visible to squeue/scontrol for an hour (no accounting here).
MinJobAge=3600
KillWait=5
InactiveLimit=0
JobRequeue=1
PlugStackConfig=$dir/plugstack.conf
NodeName=$node NodeHostname=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
# Jobs in "urgent" preempt jobs in "debug", which go back to the queue (what a
# cluster's preemption does to the service's jobs; the requeue test uses it).
PreemptType=preempt/partition_prio
PreemptMode=REQUEUE
PartitionName=debug Nodes=$node Default=YES MaxTime=INFINITE State=UP PriorityTier=1
PartitionName=urgent Nodes=$node MaxTime=INFINITE State=UP PriorityTier=2 PreemptMode=OFF
EOF
: >"$dir/plugstack.conf"
export SLURM_CONF="$dir/slurm.conf"

slurmctld -i -f "$SLURM_CONF" >"$dir/slurmctld.out" 2>&1 ||
  skip "slurmctld did not start: $(tail -5 "$dir/slurmctld.log" "$dir/slurmctld.out" 2>/dev/null)"
slurmd -N "$node" -f "$SLURM_CONF" >"$dir/slurmd.out" 2>&1 ||
  skip "slurmd did not start: $(tail -5 "$dir/slurmd.log" "$dir/slurmd.out" 2>/dev/null)"

# Ready when the node is idle (at most 30 s).
for _ in $(seq 150); do
  state=$(timeout 5 sinfo -h -N -n "$node" -o %t 2>/dev/null || true)
  case "$state" in
    idle*|mix*|alloc*) echo "SLURM_CONF=$SLURM_CONF"; exit 0 ;;
  esac
  sleep 0.2
done
skip "the node did not come up (state '${state:-none}'): $(tail -5 "$dir/slurmd.log" 2>/dev/null)"
