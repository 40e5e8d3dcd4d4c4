#!/usr/bin/env bash
# A single-node SLURM cluster on this Debian/Ubuntu machine from Debian's packages, for trying the SLURM path for
# real:
#   sudo bash scripts/slurm_single_node.sh start [--accounting]   # install (apt-get) what is missing, write the
#                                                                 # configuration, start the daemons
#   bash scripts/slurm_single_node.sh status
#   sudo bash scripts/slurm_single_node.sh stop                   # every daemon this script started, and waits
# One partition `cpu` (Default) with every CPU and 90 % of the memory of this machine. Without --accounting:
# slurmctld, slurmd, munged; sacct has nothing (the harness must report a dead job without it). With --accounting:
# also MariaDB (local socket only, no TCP port) and slurmdbd, AccountingStorageType=accounting_storage/slurmdbd,
# the cluster `bench`, the account `bench` and the users root and $SUDO_USER registered with sacctmgr, jobs without
# an association refused (AccountingStorageEnforce=associations). Either way memory is enforced by polling
# (jobacct_gather/linux with OverMemoryKill, every 2 s), not by cgroups: in a container the cgroup hierarchy is
# the host's, and task/cgroup would create cgroups outside the container's own. `start` is idempotent: daemons
# already running are kept, and restarted only where the configuration changed (switching mode). `stop` stops the
# SLURM daemons, and munged and MariaDB only where this script started them (/run/slurm_single_node).
# Not for production clusters (SlurmUser=root, no cgroups).
set -euo pipefail
action="${1:-start}"
mode="${2:-}"
conf_dir=/etc/slurm
state_dir=/var/spool/slurmctld
node="$(hostname -s)"
db_sock=/run/mysqld/mysqld.sock
db_pid=/run/mysqld/mysqld.pid
ours=/run/slurm_single_node   # a file per shared daemon this script started (munged, MariaDB): only those are stopped

need_root() { [ "$(id -u)" = 0 ] || { echo "error: $0 $action: run as root (sudo)" >&2; exit 2; }; }

install() {   # install <command>... : apt-get the packages of the missing commands
    local packages=() cmd
    for cmd in "$@"; do
        command -v "$cmd" >/dev/null && continue
        case "$cmd" in
            slurmctld) packages+=(slurmctld) ;; slurmd) packages+=(slurmd) ;; sbatch) packages+=(slurm-client) ;;
            munged) packages+=(munge) ;; slurmdbd) packages+=(slurmdbd) ;; mariadbd) packages+=(mariadb-server) ;;
        esac
    done
    [ "${#packages[@]}" = 0 ] && return
    # policy-rc.d (containers) or a missing init keep the packages' own services from starting: this script starts
    # the daemons itself
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${packages[@]}"
}

write_if_changed() {   # write_if_changed <file> <mode>: stdin into <file>; exit status 0 when it changed
    local new
    new="$(cat)"
    if [ -f "$1" ] && [ "$(cat "$1")" = "$new" ]; then return 1; fi
    printf '%s\n' "$new" > "$1.tmp" && chmod "$2" "$1.tmp" && mv "$1.tmp" "$1"
}

slurm_conf() {   # slurm_conf accounting|none
    local cpus mem_mb
    cpus="$(nproc)"
    mem_mb="$(awk '/MemTotal/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)"
    cat <<CONF
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
JobAcctGatherType=jobacct_gather/linux
JobAcctGatherFrequency=task=2
JobAcctGatherParams=OverMemoryKill
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MpiDefault=none
CONF
    if [ "$1" = accounting ]; then
        cat <<CONF
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=$node
AccountingStorageEnforce=associations
CONF
    else
        echo "AccountingStorageType=accounting_storage/none"
    fi
    cat <<CONF
NodeName=$node CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=cpu Nodes=$node Default=YES MaxTime=INFINITE State=UP
CONF
}

running() { [ -s "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }   # running <pid file>

stop_daemon() {   # stop_daemon <name> <pid file>: SIGTERM, then wait up to 60 s for it to exit
    running "$2" || return 0
    local pid
    pid="$(cat "$2")"
    kill "$pid" 2>/dev/null || true
    for _ in $(seq 120); do kill -0 "$pid" 2>/dev/null || { echo "stopped $1"; return 0; }; sleep 0.5; done
    echo "error: $1 (pid $pid) did not stop within 60 s" >&2
    return 1
}

wait_for() {   # wait_for <what> <seconds> <command...>
    local what="$1" seconds="$2"
    shift 2
    for _ in $(seq "$seconds"); do "$@" >/dev/null 2>&1 && return 0; sleep 1; done
    echo "error: slurm: $what did not come up within $seconds s; see /var/log/slurm/ and /var/log/mysql/" >&2
    exit 1
}

start_munge() {
    [ -s /etc/munge/munge.key ] || { mungekey --create 2>/dev/null || create-munge-key -f; }
    chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
    mkdir -p /run/munge && chown munge:munge /run/munge
    running /run/munge/munged.pid && return
    runuser -u munge -- /usr/sbin/munged
    mkdir -p "$ours" && touch "$ours/munged"
}

start_database() {   # MariaDB on its socket only, the accounting database and its user, then slurmdbd
    local pass
    mkdir -p /run/mysqld /var/log/mysql && chown mysql:mysql /run/mysqld /var/log/mysql
    [ -d /var/lib/mysql/mysql ] || mariadb-install-db --user=mysql --datadir=/var/lib/mysql >/dev/null
    if ! running "$db_pid"; then
        # innodb_lock_wait_timeout as slurmdbd's documentation asks; no TCP port (slurmdbd uses the socket)
        setsid /usr/sbin/mariadbd --user=mysql --skip-networking --socket="$db_sock" --pid-file="$db_pid" \
            --innodb-lock-wait-timeout=900 --log-error=/var/log/mysql/error.log </dev/null >/dev/null 2>&1 &
        mkdir -p "$ours" && touch "$ours/mariadb"
    fi
    wait_for MariaDB 60 mariadb-admin --socket="$db_sock" ping
    # the database password lives in slurmdbd.conf only (mode 600); kept across starts
    pass="$(sed -n 's/^StoragePass=//p' "$conf_dir/slurmdbd.conf" 2>/dev/null || true)"
    [ -n "$pass" ] || pass="$(od -An -N16 -tx1 /dev/urandom | tr -d ' \n')"
    mariadb --socket="$db_sock" <<SQL
CREATE DATABASE IF NOT EXISTS slurm_acct_db;
CREATE USER IF NOT EXISTS 'slurm'@'localhost' IDENTIFIED BY '$pass';
ALTER USER 'slurm'@'localhost' IDENTIFIED BY '$pass';
GRANT ALL ON slurm_acct_db.* TO 'slurm'@'localhost';
SQL
    if write_if_changed "$conf_dir/slurmdbd.conf" 600 <<CONF
AuthType=auth/munge
DbdHost=$node
SlurmUser=root
StorageType=accounting_storage/mysql
StorageHost=localhost
StorageUser=slurm
StoragePass=$pass
StorageLoc=slurm_acct_db
LogFile=/var/log/slurm/slurmdbd.log
PidFile=/run/slurmdbd.pid
CONF
    then stop_daemon slurmdbd /run/slurmdbd.pid; fi
    running /run/slurmdbd.pid || /usr/sbin/slurmdbd
    wait_for slurmdbd 60 sacctmgr -n show cluster
}

register() {   # the cluster, the account and the users (sacctmgr), each only where missing
    local user
    [ -n "$(sacctmgr -n -P show cluster bench format=cluster)" ] || sacctmgr -i add cluster bench
    [ -n "$(sacctmgr -n -P show account bench format=account)" ] || \
        sacctmgr -i add account bench Cluster=bench Description="mm2fsk-bench sweeps" Organization=bench
    for user in root ${SUDO_USER:-}; do
        [ -n "$(sacctmgr -n -P show assoc where user="$user" account=bench format=user)" ] || \
            sacctmgr -i add user "$user" Account=bench DefaultAccount=bench Cluster=bench
    done
}

start() {
    need_root
    local accounting=none changed=0
    case "$mode" in --accounting) accounting=accounting ;; "") ;;
        *) echo "error: $0 start: unknown option '$mode' (--accounting)" >&2; exit 2 ;; esac
    install slurmctld slurmd sbatch munged
    [ "$accounting" = none ] || install slurmdbd mariadbd
    mkdir -p "$conf_dir" "$state_dir" /var/spool/slurmd /var/log/slurm
    start_munge
    # first the configuration: sacctmgr finds slurmdbd through it
    slurm_conf "$accounting" | write_if_changed "$conf_dir/slurm.conf" 644 && changed=1
    if [ "$accounting" = accounting ]; then
        start_database
        register
    fi
    if [ "$changed" = 1 ]; then   # AccountingStorageType is read at start only: restart, not reconfigure
        stop_daemon slurmd /run/slurmd.pid
        stop_daemon slurmctld /run/slurmctld.pid
    fi
    if [ "$accounting" = none ]; then   # a database left from an accounting run is no longer needed
        stop_daemon slurmdbd /run/slurmdbd.pid
        stop_database
    fi
    running /run/slurmctld.pid || /usr/sbin/slurmctld
    running /run/slurmd.pid || /usr/sbin/slurmd
    for _ in $(seq 30); do
        if sinfo -h -o %T 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
            sinfo
            [ "$accounting" = none ] || sacctmgr -n show assoc format=cluster,account,user
            exit 0
        fi
        scontrol update nodename="$node" state=resume >/dev/null 2>&1 || true
        sleep 1
    done
    echo "error: slurm: the node did not come up; see /var/log/slurm/slurmctld.log and slurmd.log" >&2
    exit 1
}

stop_database() {   # only a MariaDB this script started (another may serve other users on this machine)
    [ -e "$ours/mariadb" ] && running "$db_pid" || return 0
    mariadb-admin --socket="$db_sock" shutdown 2>/dev/null || true   # a clean InnoDB shutdown; else SIGTERM
    stop_daemon MariaDB "$db_pid" && rm -f "$ours/mariadb"
}

stop() {
    need_root
    stop_daemon slurmd /run/slurmd.pid
    stop_daemon slurmctld /run/slurmctld.pid
    stop_daemon slurmdbd /run/slurmdbd.pid
    stop_database
    if [ -e "$ours/munged" ] && running /run/munge/munged.pid; then
        munged --stop >/dev/null 2>&1 || stop_daemon munged /run/munge/munged.pid
    fi
    rm -f "$ours/munged"
}

status() {
    sinfo && squeue
    if grep -q '^AccountingStorageType=accounting_storage/slurmdbd' "$conf_dir/slurm.conf" 2>/dev/null; then
        sacctmgr -n show assoc format=cluster,account,user
    else
        echo "no accounting"
    fi
}

case "$action" in
    start) start ;;
    stop) stop ;;
    status) status ;;
    *) echo "error: $0: unknown action '$action' (start [--accounting] | stop | status)" >&2; exit 2 ;;
esac
