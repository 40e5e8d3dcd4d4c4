#!/usr/bin/env bash
# A single-node SLURM cluster on this Debian/Ubuntu machine (Debian's slurmctld, slurmd and munge packages), for
# trying the SLURM path for real:
#   sudo bash scripts/slurm_single_node.sh start    # install (apt-get) if missing, write a slurm.conf, start the daemons
#   bash scripts/slurm_single_node.sh status
#   sudo bash scripts/slurm_single_node.sh stop
# One partition `cpu` (Default) with every CPU and the memory of this machine, no accounting (sacct has nothing:
# the harness must report a dead job without it), no cgroups (works in containers). Not for production clusters.
set -euo pipefail
action="${1:-start}"
conf_dir=/etc/slurm
state_dir=/var/spool/slurmctld
node="$(hostname -s)"

need_root() { [ "$(id -u)" = 0 ] || { echo "error: $0 $action: run as root (sudo)" >&2; exit 2; }; }

install() {
    command -v slurmctld >/dev/null && command -v slurmd >/dev/null && command -v munged >/dev/null && \
        command -v sbatch >/dev/null && return
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends slurmctld slurmd slurm-client munge
}

write_conf() {
    local cpus mem_mb
    cpus="$(nproc)"
    mem_mb="$(awk '/MemTotal/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)"
    mkdir -p "$conf_dir" "$state_dir" /var/spool/slurmd /var/log/slurm
    cat > "$conf_dir/slurm.conf" <<CONF
ClusterName=bench
SlurmctldHost=$node
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$state_dir
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MpiDefault=none
NodeName=$node CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=cpu Nodes=$node Default=YES MaxTime=INFINITE State=UP
CONF
}

start() {
    need_root
    install
    write_conf
    [ -s /etc/munge/munge.key ] || { mungekey --create 2>/dev/null || create-munge-key -f; }
    chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
    mkdir -p /run/munge && chown munge:munge /run/munge
    pgrep -x munged >/dev/null || runuser -u munge -- /usr/sbin/munged
    pgrep -x slurmctld >/dev/null || /usr/sbin/slurmctld
    pgrep -x slurmd >/dev/null || /usr/sbin/slurmd
    for _ in $(seq 30); do
        if sinfo -h -o %T 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
            sinfo; exit 0
        fi
        scontrol update nodename="$node" state=resume >/dev/null 2>&1 || true
        sleep 1
    done
    echo "error: slurm: the node did not come up; see /var/log/slurm/slurmctld.log and slurmd.log" >&2
    exit 1
}

stop() {
    need_root
    for daemon in slurmd slurmctld; do
        pid_file="/run/$daemon.pid"
        [ -s "$pid_file" ] && kill "$(cat "$pid_file")" 2>/dev/null || true
    done
}

case "$action" in
    start) start ;;
    stop) stop ;;
    status) sinfo && squeue ;;
    *) echo "error: $0: unknown action '$action' (start | stop | status)" >&2; exit 2 ;;
esac
