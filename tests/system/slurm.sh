#!/bin/sh
# A real single-node Slurm for the tests: Debian's slurm-wlm and munge, started without systemd and
# stopped by the pids this script recorded (docs/slurm.md, "A real Slurm in the tests").
#
#   tests/system/slurm.sh install   apt-get install slurm-wlm munge (root), unless already there
#   tests/system/slurm.sh start     install, write the configuration, start munged, slurmctld, slurmd
#                                   and wait until the node is idle; a no-op when they already run
#   tests/system/slurm.sh stop      kill exactly the pids `start` recorded
#   tests/system/slurm.sh status    say what runs; exit 0 when the node answers, else 1
#
# Everything lives in $SHAKEFLOW_SLURM_DIR (default ~/.cache/shakeflow/slurm): slurm.conf, state,
# spool, logs, pids. Clients find it through SLURM_CONF=$SHAKEFLOW_SLURM_DIR/slurm.conf (the
# tests set it themselves; `make test` exports it). Only munge's own files stay where Debian puts
# them: the key in /etc/munge and its socket in /run/munge, which every client of munge expects.
set -eu

DIR=${SHAKEFLOW_SLURM_DIR:-$HOME/.cache/shakeflow/slurm}
CONF=$DIR/slurm.conf
NODE=$(hostname -s)
export SLURM_CONF="$CONF"

say() { echo "slurm.sh: $*" >&2; }
die() { say "$*"; exit 1; }

# A pid recorded by `start` that is still the process we started (its command name matches).
alive() { # name pidfile
    [ -f "$2" ] || return 1
    pid=$(cat "$2")
    [ -n "$pid" ] && [ -r "/proc/$pid/comm" ] && [ "$(cat "/proc/$pid/comm")" = "$1" ]
}

install() {
    if command -v slurmctld >/dev/null && command -v slurmd >/dev/null && command -v munged >/dev/null \
        && command -v sbatch >/dev/null; then
        return 0
    fi
    [ "$(id -u)" = 0 ] || die "Slurm is not installed and installing it needs root: run \`sudo apt-get install slurm-wlm munge\`, then \`$0 start\` as root (or \`make test\` as root)"
    command -v apt-get >/dev/null || die "Slurm is not installed and this is not a Debian/Ubuntu system: install slurm-wlm and munge, then run \`$0 start\`"
    say "installing slurm-wlm and munge"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null
}

write_conf() {
    mkdir -p "$DIR/state" "$DIR/spool" "$DIR/log"
    # RealMemory above what slurmd measures drains the node: take what it measures, less 5 %.
    mem=$(slurmd -C 2>/dev/null | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p')
    cpus=$(slurmd -C 2>/dev/null | sed -n 's/.*CPUs=\([0-9]*\).*/\1/p')
    [ -n "$mem" ] && [ -n "$cpus" ] || die "\`slurmd -C\` did not report this node's CPUs and memory"
    mem=$((mem * 95 / 100))
    cat >"$CONF.tmp" <<CONF
# Written by tests/system/slurm.sh: one node, no cgroups, no accounting database.
ClusterName=shakeflow
SlurmctldHost=$NODE
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CryptoType=crypto/munge
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/slurmctld.pid.slurm
SlurmdPidFile=$DIR/slurmd.pid.slurm
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
# No slurmdbd: sacct answers "accounting storage is disabled"; finished jobs are kept in
# slurmctld for an hour (MinJobAge) and written to the job completion file.
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/filetxt
JobCompLoc=$DIR/log/jobcomp.txt
MinJobAge=3600
MaxArraySize=1001
MaxJobCount=10000
SchedulerParameters=sched_interval=2
NodeName=$NODE CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
CONF
    mv "$CONF.tmp" "$CONF"
}

start_munge() {
    if alive munged "$DIR/munged.pid"; then return 0; fi
    [ -f /etc/munge/munge.key ] || mungekey --create --keyfile=/etc/munge/munge.key
    chown munge:munge /etc/munge/munge.key && chmod 600 /etc/munge/munge.key
    mkdir -p /run/munge /var/lib/munge /var/log/munge
    chown munge:munge /run/munge /var/lib/munge /var/log/munge
    chmod 755 /run/munge
    # munged in the foreground (-F), as user munge, detached from this shell: its pid is $!.
    setsid setpriv --reuid=munge --regid=munge --init-groups /usr/sbin/munged -F >"$DIR/log/munged.out" 2>&1 &
    echo $! >"$DIR/munged.pid"
    i=0
    until munge -n </dev/null >/dev/null 2>&1; do
        i=$((i + 1)); [ $i -lt 100 ] || die "munged did not start: $(cat "$DIR/log/munged.out")"
        sleep 0.1
    done
    alive munged "$DIR/munged.pid" || die "munged exited (is another munged serving /run/munge?): $(cat "$DIR/log/munged.out")"
}

start_daemon() { # name
    if alive "$1" "$DIR/$1.pid"; then return 0; fi
    setsid "/usr/sbin/$1" -D -f "$CONF" >"$DIR/log/$1.out" 2>&1 &
    echo $! >"$DIR/$1.pid"
}

start() {
    [ "$(id -u)" = 0 ] || die "starting the test Slurm needs root (its daemons run jobs as their submitters): run \`$0 start\` as root, or \`make test\` as root"
    install
    getent hosts "$NODE" >/dev/null || die "the node name \`$NODE\` (short host name) does not resolve: add \`127.0.0.1 $NODE\` to /etc/hosts"
    if alive slurmctld "$DIR/slurmctld.pid" && alive slurmd "$DIR/slurmd.pid" && alive munged "$DIR/munged.pid"; then
        say "already running (SLURM_CONF=$CONF)"
        return 0
    fi
    write_conf
    start_munge
    start_daemon slurmctld
    start_daemon slurmd
    # Wait for the node to be idle: slurmctld answers, slurmd registered.
    i=0
    until [ "$(sinfo -h -n "$NODE" -o %t 2>/dev/null)" = idle ] || [ "$(sinfo -h -n "$NODE" -o %t 2>/dev/null)" = mix ]; do
        i=$((i + 1))
        if [ $i -ge 600 ]; then
            say "the node did not become idle in 60 s; sinfo says: $(sinfo -h -N 2>&1)"
            tail -n 20 "$DIR/log/slurmctld.log" "$DIR/log/slurmd.log" >&2 || true
            exit 1
        fi
        # A node drained by an earlier configuration (e.g. a larger RealMemory) is brought back.
        case "$(sinfo -h -n "$NODE" -o %t 2>/dev/null)" in
            drain*|down*) scontrol update nodename="$NODE" state=resume >/dev/null 2>&1 || true ;;
        esac
        sleep 0.1
    done
    for name in munged slurmctld slurmd; do
        alive "$name" "$DIR/$name.pid" || die "$name exited; see $DIR/log/"
    done
    say "running: SLURM_CONF=$CONF, node $NODE idle"
}

stop() {
    for name in slurmd slurmctld munged; do
        if alive "$name" "$DIR/$name.pid"; then
            pid=$(cat "$DIR/$name.pid")
            kill "$pid"
            i=0
            while [ -d "/proc/$pid" ] && [ $i -lt 100 ]; do sleep 0.1; i=$((i + 1)); done
            [ -d "/proc/$pid" ] && kill -9 "$pid"
        fi
        rm -f "$DIR/$name.pid"
    done
}

status() {
    for name in munged slurmctld slurmd; do
        if alive "$name" "$DIR/$name.pid"; then echo "$name: running, pid $(cat "$DIR/$name.pid")"; else echo "$name: not running"; fi
    done
    echo "SLURM_CONF=$CONF"
    sinfo -h -N -o '%N %t %c %m' 2>/dev/null || return 1
}

case "${1:-}" in
    install) install ;;
    start) start ;;
    stop) stop ;;
    status) status ;;
    *) die "usage: $0 {install|start|stop|status}" ;;
esac
