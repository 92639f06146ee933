#!/usr/bin/env bash
# Runs a sweep on a real single-node Slurm (Debian's slurm-wlm and munge, started here without
# systemd) as a 3-task job array plus a dependent merge job, and checks that its tables are
# byte-identical to the single-process run of the same sweep. Installs the packages where it can;
# prints why and exits 0 where it cannot (no root, no apt, no package).
#
#   scripts/slurm/test-local.sh <calsim binary> [sweep file]
set -euo pipefail
calsim=$(realpath "${1:?usage: $0 <calsim binary> [sweep file]}")
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
work=$(mktemp -d /tmp/calsim-slurm.XXXXXX)
# The work directory goes at exit, after the daemons, unless something failed (then its logs stay).
keep=0
stop() {
    local pidfile
    for pidfile in "$work/slurmd.pid" "$work/slurmctld.pid"; do
        [ -f "$pidfile" ] || continue
        local pid
        pid=$(cat "$pidfile")
        kill "$pid" 2>/dev/null || true
        for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    done
}
finish() {
    local rc=$?
    scancel --quiet --user="$(id -un)" 2>/dev/null || true
    stop
    if [ "$rc" = 0 ] && [ "$keep" = 0 ]; then
        rm -rf "$work"
    else
        echo "slurm test: logs kept in $work" >&2
    fi
}
trap finish EXIT
skip() { echo "slurm test skipped: $*"; exit 0; }

if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    [ "$(id -u)" = 0 ] || skip "slurm-wlm and munge are not installed and this is not root"
    command -v apt-get >/dev/null || skip "slurm-wlm and munge are not installed and there is no apt-get"
    echo "slurm test: installing slurm-wlm and munge"
    { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y slurm-wlm munge; } >"$work/apt.log" 2>&1 \
        || { keep=1; skip "apt-get install slurm-wlm munge failed (see $work/apt.log)"; }
fi
[ "$(id -u)" = 0 ] || skip "starting slurmctld and slurmd here needs root"

if [ $# -ge 2 ]; then
    sweep=$(realpath "$2")
else
    sweep="$work/slurm_ci.toml"
    cat >"$sweep" <<TOML
base = "$repo/scenarios/ci_quick.toml"
realisations = 3
thresholds_mm = [0.5, 1.0]
[fixed]
"study.set_sizes" = [20, 30]
"study.table_set_size" = 30
"study.repetitions" = 2
[[axis]]
key = "trical.epsilon_mm"
values = [0.010, 0.020]
TOML
fi
name=$(basename "$sweep" .toml)

# munge: a key of its own, the daemon in the foreground of a background job.
mkdir -p /etc/munge /var/log/munge /var/lib/munge /run/munge
[ -s /etc/munge/munge.key ] || dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
chown -R munge:munge /etc/munge /var/log/munge /var/lib/munge /run/munge 2>/dev/null || true
chmod 0700 /etc/munge; chmod 0400 /etc/munge/munge.key
pgrep -x munged >/dev/null || runuser -u munge -- /usr/sbin/munged || /usr/sbin/munged --force

host=$(hostname -s)
cpus=$(nproc)
mem=$(awk '/MemTotal/ {print int($2 / 1024 * 0.8)}' /proc/meminfo)
export SLURM_CONF="$work/slurm.conf"
mkdir -p "$work/ctld" "$work/d"
cat >"$SLURM_CONF" <<CONF
ClusterName=calsim
SlurmctldHost=$host
SlurmUser=root
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
MpiDefault=none
ReturnToService=2
StateSaveLocation=$work/ctld
SlurmdSpoolDir=$work/d
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=calsim Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
slurmctld -i -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF"
for _ in $(seq 60); do
    sinfo -h -o %t 2>/dev/null | grep -qE '^(idle|mix|alloc)' && break
    sleep 1
done
sinfo -h -o %t | grep -qE '^(idle|mix|alloc)' || { cat "$work/slurmctld.log" "$work/slurmd.log" >&2 || true; echo "slurm test: the node did not come up" >&2; exit 1; }
echo "slurm test: single-node Slurm up ($(sinfo -h -o '%P %D %t %c'))"

"$calsim" sweep "$sweep" --out "$work/single" >/dev/null
read -r array merge < <("$here/submit.sh" "$calsim" "$sweep" "$work/slurm" 3 --cpus-per-task=1)
echo "slurm test: array job $array (3 tasks), merge job $merge (afterok)"
for _ in $(seq 600); do
    [ -z "$(squeue -h -j "$array,$merge" 2>/dev/null)" ] && break
    sleep 1
done
[ -z "$(squeue -h -j "$array,$merge" 2>/dev/null)" ] || { echo "slurm test: jobs still queued after 600 s" >&2; squeue >&2; exit 1; }
status=0
for t in sweep.parquet points.parquet; do
    a=$(sha256sum "$work/single/$name/$t" | cut -d' ' -f1)
    b=$(sha256sum "$work/slurm/$name/$t" 2>/dev/null | cut -d' ' -f1 || true)
    echo "slurm test: $t single process $a, Slurm array of 3 + merge ${b:-missing}"
    [ "$a" = "$b" ] || status=1
done
if [ $status = 0 ]; then
    echo "slurm: 1 passed, 0 failed"
else
    cat "$work"/slurm/*.out >&2 2>/dev/null || true
    echo "slurm: 0 passed, 1 failed"
fi
exit $status
