#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for trying the job array (and for the test in
# tests/slurm.rs): munge, slurmctld and slurmd with a generated slurm.conf, all state under DIR.
#
#   examples/slurm/local-cluster.sh start DIR   # prints `export SLURM_CONF=DIR/slurm.conf`
#   examples/slurm/local-cluster.sh stop DIR
#
# Needs Debian's slurm-wlm and munge packages (`apt-get install slurm-wlm munge`); run as the
# user the jobs should run as (root on CI). Ports 16817/16818 unless SLURM_PORT_BASE is set.
set -euo pipefail
cmd=${1:?usage: local-cluster.sh start|stop DIR}
dir=$(realpath -m "${2:?usage: local-cluster.sh start|stop DIR}")
conf="$dir/slurm.conf"
case "$cmd" in
start)
    for b in munged slurmctld slurmd sbatch; do
        command -v "$b" >/dev/null || PATH="$PATH:/usr/sbin"
        command -v "$b" >/dev/null || { echo "local-cluster.sh: $b not found (apt-get install slurm-wlm munge)" >&2; exit 3; }
    done
    mkdir -p "$dir"/{state,spool,log,munge}
    chmod 700 "$dir/munge"
    base=${SLURM_PORT_BASE:-16817}
    host=$(hostname -s)
    user=$(id -un)
    cat > "$conf" <<CONF
ClusterName=umbrasweep
SlurmctldHost=$host
SlurmUser=$user
SlurmdUser=$user
AuthType=auth/munge
CryptoType=crypto/munge
AuthInfo=socket=$dir/munge/munge.sock
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
SlurmctldPort=$base
SlurmdPort=$((base + 1))
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
NodeName=$host CPUs=$(nproc) State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
    dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none
    chmod 600 "$dir/munge/munge.key"
    munged --force --key-file="$dir/munge/munge.key" --socket="$dir/munge/munge.sock" \
        --pid-file="$dir/munge/munged.pid" --log-file="$dir/munge/munged.log" \
        --seed-file="$dir/munge/seed"
    slurmctld -f "$conf"
    slurmd -f "$conf"
    export SLURM_CONF="$conf"
    for _ in $(seq 1 60); do
        if sinfo -h -o %T 2>/dev/null | grep -q idle; then
            echo "export SLURM_CONF=$conf"
            exit 0
        fi
        sleep 0.5
    done
    echo "local-cluster.sh: the node did not come up; logs in $dir/log" >&2
    exit 4
    ;;
stop)
    export SLURM_CONF="$conf"
    scontrol shutdown >/dev/null 2>&1 || true
    for pidfile in "$dir/slurmd.pid" "$dir/slurmctld.pid" "$dir/munge/munged.pid"; do
        if [ -f "$pidfile" ]; then
            pid=$(cat "$pidfile")
            for _ in $(seq 1 20); do kill -0 "$pid" 2>/dev/null || break; sleep 0.25; done
            kill "$pid" 2>/dev/null || true
        fi
    done
    ;;
*)
    echo "usage: local-cluster.sh start|stop DIR" >&2
    exit 2
    ;;
esac
