#!/bin/sh
# A real multi-node Slurm for the tests: Debian's slurm-wlm and munge, started without systemd and
# stopped by the pids this script recorded (docs/slurm.md, "A real Slurm in the tests").
#
#   tests/system/slurm.sh install          apt-get install slurm-wlm munge (root), unless already there
#   tests/system/slurm.sh start            install, write the configuration, start munged, slurmctld
#                                          and one slurmd per node, and wait until the nodes are idle;
#                                          starts only what is not running (a killed node comes back)
#   tests/system/slurm.sh stop             kill exactly the pids `start` recorded
#   tests/system/slurm.sh status           say what runs; exit 0 when the nodes answer, else 1
#   tests/system/slurm.sh kill-node NODE   SIGKILL every process of NODE (its slurmd and the job
#                                          steps it runs), as a node that crashed
#
# The nodes are slurmd processes of this machine, each started as `slurmd -N <node>` in a UTS
# namespace of its own whose host name is the node's (what a job sees), each on its own port of
# the loopback address (Slurm's multiple-slurmd mode); they share the file system, as a cluster's
# nodes share Lustre or NFS. Partition `debug` (the default) has n1 and n2; partition `lossy` has
# n3 alone, for the test that kills a node mid-run without touching the others' jobs.
#
# Everything lives in $SHAKEFLOW_SLURM_DIR (default ~/.cache/shakeflow/slurm): slurm.conf, state,
# spool, logs, pids. Clients find it through SLURM_CONF=$SHAKEFLOW_SLURM_DIR/slurm.conf (the
# tests set it themselves; `make test` exports it). Only munge's own files stay where Debian puts
# them: the key in /etc/munge and its socket in /run/munge, which every client of munge expects.
set -eu

DIR=${SHAKEFLOW_SLURM_DIR:-$HOME/.cache/shakeflow/slurm}
CONF=$DIR/slurm.conf
NODE=$(hostname -s)
SHARED="n1 n2"
LOSSY="n3"
NODES="$SHARED $LOSSY"
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
    mkdir -p "$DIR/state" "$DIR/log"
    for node in $NODES; do mkdir -p "$DIR/spool/$node"; done
    # RealMemory above what slurmd measures drains the node: take what it measures, less 5 %.
    mem=$(slurmd -C 2>/dev/null | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p')
    cpus=$(slurmd -C 2>/dev/null | sed -n 's/.*CPUs=\([0-9]*\).*/\1/p')
    [ -n "$mem" ] && [ -n "$cpus" ] || die "\`slurmd -C\` did not report this node's CPUs and memory"
    # The machine's CPUs and memory shared out between the nodes (a node claiming more than
    # slurmd measures is drained).
    count=$(echo $SHARED | wc -w)
    cpus=$((cpus / count)); [ "$cpus" -ge 1 ] || cpus=1
    mem=$((mem * 95 / 100 / count))
    nodes=$(echo $NODES | tr ' ' ',')
    shared=$(echo $SHARED | tr ' ' ',')
    cat >"$CONF.tmp" <<CONF
# Written by tests/system/slurm.sh: nodes $nodes (slurmd -N, one UTS namespace each), no cgroups,
# no accounting database.
ClusterName=shakeflow
SlurmctldHost=$NODE
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CryptoType=crypto/munge
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool/%n
SlurmctldPidFile=$DIR/slurmctld.pid.slurm
SlurmdPidFile=$DIR/slurmd-%n.pid.slurm
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd-%n.log
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
# A node that stops answering is down after 10 s, and its jobs with it (NODE_FAIL).
SlurmdTimeout=10
CONF
    port=6820
    for node in $NODES; do
        port=$((port + 1))
        echo "NodeName=$node NodeHostname=$node NodeAddr=127.0.0.1 Port=$port CPUs=$cpus RealMemory=$mem State=UNKNOWN" >>"$CONF.tmp"
    done
    echo "PartitionName=debug Nodes=$shared Default=YES MaxTime=INFINITE State=UP" >>"$CONF.tmp"
    echo "PartitionName=lossy Nodes=$LOSSY MaxTime=INFINITE State=UP" >>"$CONF.tmp"
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

# One node: `slurmd -N <node>` in a new UTS namespace named after it (unshare and sh exec, so the
# recorded pid is slurmd's).
start_node() { # node
    if alive slurmd "$DIR/slurmd-$1.pid"; then return 0; fi
    setsid unshare --uts sh -c "hostname '$1' && exec /usr/sbin/slurmd -D -N '$1' -f '$CONF'" >"$DIR/log/slurmd-$1.out" 2>&1 &
    echo $! >"$DIR/slurmd-$1.pid"
}

# Every node answers (idle or running jobs).
nodes_up() {
    for node in $NODES; do
        case "$(sinfo -h -n "$node" -o %t 2>/dev/null)" in
            idle|mix|alloc) ;;
            *) return 1 ;;
        esac
    done
}

start() {
    [ "$(id -u)" = 0 ] || die "starting the test Slurm needs root (its daemons run jobs as their submitters): run \`$0 start\` as root, or \`make test\` as root"
    install
    getent hosts "$NODE" >/dev/null || die "the controller's name \`$NODE\` (short host name) does not resolve: add \`127.0.0.1 $NODE\` to /etc/hosts"
    command -v unshare >/dev/null || die "\`unshare\` (util-linux) is needed to give each node its host name"
    all=yes
    for node in $NODES; do alive slurmd "$DIR/slurmd-$node.pid" || all=; done
    if [ -n "$all" ] && alive slurmctld "$DIR/slurmctld.pid" && alive munged "$DIR/munged.pid"; then
        say "already running (SLURM_CONF=$CONF)"
        return 0
    fi
    # The configuration is rewritten only while slurmctld is down (a node coming back keeps it).
    alive slurmctld "$DIR/slurmctld.pid" || write_conf
    start_munge
    start_daemon slurmctld
    for node in $NODES; do start_node "$node"; done
    # Wait for the nodes to answer: slurmctld up, every slurmd registered.
    i=0
    until nodes_up; do
        i=$((i + 1))
        if [ $i -ge 600 ]; then
            say "the nodes did not become idle in 60 s; sinfo says: $(sinfo -h -N 2>&1)"
            tail -n 20 "$DIR/log/slurmctld.log" "$DIR"/log/slurmd-*.log >&2 || true
            exit 1
        fi
        # A node drained or down (an earlier configuration, a node killed) is brought back.
        for node in $NODES; do
            case "$(sinfo -h -n "$node" -o %t 2>/dev/null)" in
                drain*|down*) scontrol update nodename="$node" state=resume >/dev/null 2>&1 || true ;;
            esac
        done
        sleep 0.1
    done
    for name in munged slurmctld; do
        alive "$name" "$DIR/$name.pid" || die "$name exited; see $DIR/log/"
    done
    for node in $NODES; do
        alive slurmd "$DIR/slurmd-$node.pid" || die "the slurmd of $node exited; see $DIR/log/"
    done
    say "running: SLURM_CONF=$CONF, nodes $(echo $NODES) idle"
}

# Every process in the UTS namespace of NODE's slurmd (slurmd, its slurmstepd, the job's tasks).
kill_node() { # node
    alive slurmd "$DIR/slurmd-$1.pid" || die "node $1 is not running"
    ns=$(readlink "/proc/$(cat "$DIR/slurmd-$1.pid")/ns/uts")
    for proc in /proc/[0-9]*; do
        [ "$(readlink "$proc/ns/uts" 2>/dev/null)" = "$ns" ] && kill -9 "${proc#/proc/}" 2>/dev/null || true
    done
    rm -f "$DIR/slurmd-$1.pid"
    say "node $1 killed"
}

stop_pid() { # name pidfile
    if alive "$1" "$2"; then
        pid=$(cat "$2")
        kill "$pid"
        i=0
        while [ -d "/proc/$pid" ] && [ $i -lt 100 ]; do sleep 0.1; i=$((i + 1)); done
        [ -d "/proc/$pid" ] && kill -9 "$pid"
    fi
    rm -f "$2"
}

stop() {
    for node in $NODES; do stop_pid slurmd "$DIR/slurmd-$node.pid"; done
    # A single-node Slurm started by an earlier version of this script.
    stop_pid slurmd "$DIR/slurmd.pid"
    for name in slurmctld munged; do stop_pid "$name" "$DIR/$name.pid"; done
}

status() {
    up=yes
    for name in munged slurmctld; do
        if alive "$name" "$DIR/$name.pid"; then echo "$name: running, pid $(cat "$DIR/$name.pid")"; else echo "$name: not running"; up=; fi
    done
    for node in $NODES; do
        if alive slurmd "$DIR/slurmd-$node.pid"; then echo "slurmd $node: running, pid $(cat "$DIR/slurmd-$node.pid")"; else echo "slurmd $node: not running"; up=; fi
    done
    echo "SLURM_CONF=$CONF"
    sinfo -h -N -o '%N %t %c %m' 2>/dev/null || return 1
    [ -n "$up" ]
}

case "${1:-}" in
    install) install ;;
    start) start ;;
    stop) stop ;;
    status) status ;;
    kill-node) [ -n "${2:-}" ] || die "usage: $0 kill-node NODE"; kill_node "$2" ;;
    *) die "usage: $0 {install|start|stop|status|kill-node NODE}" ;;
esac
