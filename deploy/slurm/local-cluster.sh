#!/bin/bash
# A single-node Slurm cluster on this machine, to try deploy/slurm without a real cluster
# (and for the test a2perf-cli/tests/slurm_sweep.rs). It uses Debian's packages
# (apt-get install slurmctld slurmd slurm-client munge), keeps every file - munge key and
# socket, slurm.conf, state, logs, pid files - under one directory, listens on its own ports
# and needs no cgroups (proctrack/linuxproc, task/none), so it touches nothing in /etc and
# does not clash with another Slurm or munge on the machine. Run it as root: slurmd starts
# jobs as the user who submitted them.
#
#   deploy/slurm/local-cluster.sh up DIR     start munged, slurmctld and slurmd; wait until
#                                            the node is idle; print the SLURM_CONF to export
#   deploy/slurm/local-cluster.sh down DIR   cancel the jobs, stop the three daemons
#   deploy/slurm/local-cluster.sh logs DIR   print the daemons' logs
#
# Environment: SLURMCTLD_PORT, SLURMD_PORT (default: free ports found in /proc/net/tcp),
# A2PERF_CLUSTER_CPUS (CPUs the node offers, default: nproc; more than the machine has lets
# more jobs run at once, sharing its cores), A2PERF_CLUSTER_WAIT (seconds to wait for the node, 60).
set -euo pipefail
# Debian puts the daemons in /usr/sbin, which is not on every PATH.
PATH=$PATH:/usr/sbin:/sbin

readonly NODE=a2perf-node
readonly PARTITION=a2perf

die() {
    echo "local-cluster.sh: $*" >&2
    exit 1
}

# Whether TCP port $1 is listened on (IPv4 or IPv6), from /proc/net/tcp*: no tool needed.
port_in_use() {
    local hex
    hex=$(printf '%04X' "$1")
    cat /proc/net/tcp /proc/net/tcp6 2>/dev/null | awk -v p=":$hex" '$2 ~ p"$" { found = 1 } END { exit !found }'
}

free_port() {
    local port tries=0
    while ((tries < 200)); do
        port=$((20000 + RANDOM % 20000))
        if ! port_in_use "$port" && [ "$port" != "${1:-}" ]; then
            echo "$port"
            return
        fi
        tries=$((tries + 1))
    done
    die "no free TCP port found between 20000 and 40000"
}

print_logs() {
    local f
    for f in "$dir"/log/*; do
        [ -f "$f" ] || continue
        echo "===== $f (last 40 lines)"
        tail -n 40 "$f"
    done
}

write_config() {
    local host cpus mem_mb ctld_port d_port
    host=$(hostname -s 2>/dev/null || uname -n)
    cpus=${A2PERF_CLUSTER_CPUS:-$(nproc)}
    # Below the machine's memory, so that slurmd's registration never finds too little.
    mem_mb=$(awk '/^MemTotal:/ { print int($2 / 1024 * 0.9) }' /proc/meminfo)
    ctld_port=${SLURMCTLD_PORT:-$(free_port)}
    d_port=${SLURMD_PORT:-$(free_port "$ctld_port")}
    cat >"$dir/slurm.conf" <<EOF
# Single-node cluster written by deploy/slurm/local-cluster.sh; every path is under $dir.
ClusterName=a2perf-local
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$d_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
# cred_expire also sets how long a requeued job waits before it may start again (default 120 s).
AuthInfo=socket=$dir/munge/munge.socket,cred_expire=10
StateSaveLocation=$dir/state/ctld
SlurmdSpoolDir=$dir/state/slurmd
SlurmctldPidFile=$dir/run/slurmctld.pid
SlurmdPidFile=$dir/run/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
JobCompType=jobcomp/filetxt
JobCompLoc=$dir/log/jobcomp.log
# No cgroups: processes are tracked through their parents, and tasks are not confined.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerParameters=sched_interval=5
MpiDefault=none
SwitchType=switch/none
MailProg=/bin/true
ReturnToService=2
# Trust the CPU count above even where it exceeds the machine's (A2PERF_CLUSTER_CPUS).
SlurmdParameters=config_overrides
# Finished jobs stay visible to scontrol for an hour.
MinJobAge=3600
# Between SIGTERM and SIGKILL when a job is cancelled, requeued or preempted: more than the
# 30 s that a2perf takes at most to checkpoint.
KillWait=60
NodeName=$NODE NodeHostname=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=$PARTITION Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
}

up() {
    local cmd
    for cmd in munged slurmctld slurmd sbatch scontrol sinfo; do
        command -v "$cmd" >/dev/null || die "$cmd not found (apt-get install slurmctld slurmd slurm-client munge)"
    done
    [ "$(id -u)" -eq 0 ] || die "run as root: slurmd starts jobs as the user who submitted them"
    [ ! -e "$dir/run/slurmctld.pid" ] || die "$dir already holds a cluster (run: $0 down $dir)"
    mkdir -p "$dir"/{munge,log,run,state/ctld,state/slurmd}
    # munged refuses a socket whose directories are not searchable by everyone.
    chmod 755 "$dir" "$dir/munge"
    if command -v mungekey >/dev/null; then
        mungekey --create --keyfile "$dir/munge/munge.key"
    else
        dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none
    fi
    chmod 600 "$dir/munge/munge.key"
    munged --socket "$dir/munge/munge.socket" --key-file "$dir/munge/munge.key" \
        --pid-file "$dir/run/munged.pid" --log-file "$dir/log/munged.log" \
        --seed-file "$dir/munge/munged.seed" ||
        { print_logs >&2; die "munged did not start"; }
    write_config
    export SLURM_CONF=$dir/slurm.conf
    slurmctld -f "$SLURM_CONF" || { print_logs >&2; die "slurmctld did not start"; }
    slurmd -f "$SLURM_CONF" -N "$NODE" || { print_logs >&2; die "slurmd did not start"; }
    local wait=${A2PERF_CLUSTER_WAIT:-60} state=
    for ((i = 0; i < wait * 2; i++)); do
        state=$(sinfo -h -n "$NODE" -o %T 2>/dev/null || true)
        [ "$state" = idle ] && break
        sleep 0.5
    done
    if [ "$state" != idle ]; then
        print_logs >&2
        die "node $NODE is '${state:-unreachable}' after ${wait} s, not idle (logs above)"
    fi
    echo "cluster up: partition $PARTITION, node $NODE ($(sinfo -h -n "$NODE" -o %c) CPUs)"
    echo "export SLURM_CONF=$SLURM_CONF"
}

# Stops the daemon whose pid file is $1: SIGTERM, then SIGKILL after 15 s.
stop_daemon() {
    local pidfile=$1 pid
    [ -f "$pidfile" ] || return 0
    pid=$(cat "$pidfile")
    if [[ $pid =~ ^[0-9]+$ ]] && kill -0 "$pid" 2>/dev/null; then
        kill -TERM "$pid" 2>/dev/null || true
        for ((i = 0; i < 30; i++)); do
            kill -0 "$pid" 2>/dev/null || break
            sleep 0.5
        done
        kill -0 "$pid" 2>/dev/null && kill -KILL "$pid" 2>/dev/null
    fi
    rm -f "$pidfile"
}

down() {
    export SLURM_CONF=$dir/slurm.conf
    if [ -f "$SLURM_CONF" ] && [ -f "$dir/run/slurmctld.pid" ]; then
        # Cancelled jobs end through slurmd (SIGTERM, SIGKILL after KillWait); wait for that,
        # so no job outlives the cluster.
        scancel --user "$(id -un)" 2>/dev/null || true
        for ((i = 0; i < 150; i++)); do
            [ -z "$(squeue -h -o %i 2>/dev/null)" ] && break
            sleep 0.5
        done
    fi
    stop_daemon "$dir/run/slurmd.pid"
    stop_daemon "$dir/run/slurmctld.pid"
    stop_daemon "$dir/run/munged.pid"
    echo "cluster down: $dir"
}

[ $# -eq 2 ] || die "usage: $0 up|down|logs DIR"
dir=$(realpath -m "$2")
case $1 in
    up) up ;;
    down) down ;;
    logs) print_logs ;;
    *) die "usage: $0 up|down|logs DIR" ;;
esac
