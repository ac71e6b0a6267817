#!/usr/bin/env bash
# A one-node SLURM cluster with accounting (munge, MariaDB, slurmdbd, slurmctld, slurmd),
# all state, logs and sockets in one folder, for testing the SLURM profile on one machine.
#
#   workflow/slurm-local/cluster.sh up STATE_DIR     install (apt, once) and start; idempotent
#   workflow/slurm-local/cluster.sh down STATE_DIR   stop every daemon it started, by recorded PID
#   workflow/slurm-local/cluster.sh env STATE_DIR    print the line that points clients at it
#
# After `up`, `export SLURM_CONF=STATE_DIR/etc/slurm.conf` (what `env` prints) and sinfo,
# sbatch, srun, squeue and sacct talk to this cluster; /etc/slurm/slurm.conf links to it
# while it is up (job steps need it there, see below), and munged serves /run/munge. Account `jamflow`, partition `debug`
# (the default), cluster `jamflow`; associations are enforced, as on a real site.
#
# Needs root and apt-get (Debian/Ubuntu packages slurmctld slurmd slurm-client munge
# mariadb-server slurmdbd); exits 77 with one line on stderr when either is missing, so a
# test can skip with that reason. No systemd and no cgroups are needed:
# ProctrackType=proctrack/linuxproc and TaskPlugin=task/none.
#
# Ports (override by environment): JAMFLOW_SLURMCTLD_PORT (6817), JAMFLOW_SLURMD_PORT
# (6818), JAMFLOW_SLURMDBD_PORT (6819), JAMFLOW_MARIADB_PORT (3306).
set -euo pipefail

PACKAGES=(slurmctld slurmd slurm-client munge mariadb-server slurmdbd)
ACCOUNT=jamflow
CLUSTER=jamflow
PARTITION=debug
CTLD_PORT=${JAMFLOW_SLURMCTLD_PORT:-6817}
SLURMD_PORT=${JAMFLOW_SLURMD_PORT:-6818}
DBD_PORT=${JAMFLOW_SLURMDBD_PORT:-6819}
DB_PORT=${JAMFLOW_MARIADB_PORT:-3306}
# daemons in start order; `down` stops them in reverse
DAEMONS=(munged mariadbd slurmdbd slurmctld slurmd)
MUNGE_RUN=/run/munge
SYSTEM_CONF=/etc/slurm/slurm.conf

die() { echo "cluster.sh: $*" >&2; exit 1; }
unavailable() { echo "cluster.sh: $*" >&2; exit 77; }

usage() { die "usage: $0 up|down|env STATE_DIR"; }

[[ $# -eq 2 ]] || usage
ACTION=$1
STATE=$(realpath -m "$2")
PIDS=$STATE/pids
ETC=$STATE/etc
LOG=$STATE/log
export SLURM_CONF=$ETC/slurm.conf

alive() {  # alive NAME: the recorded PID runs the named program (or setpriv, just before its exec)
    local pidfile=$PIDS/$1.pid pid comm
    [[ -f $pidfile ]] || return 1
    pid=$(<"$pidfile")
    comm=$(cat "/proc/$pid/comm" 2>/dev/null) || return 1
    [[ $comm == "$1" || $comm == setpriv ]]
}

show_log() {  # show_log NAME: the end of a daemon's output and log (munged and mariadbd log beside their data)
    local f
    for f in "$LOG/$1.out" "$LOG/$1.log" "$STATE/munge/$1.log" "$STATE/mysql/$1.log"; do
        [[ -s $f ]] && { echo "--- $f" >&2; tail -n 15 "$f" >&2; }
    done
    return 0
}

wait_for() {  # wait_for SECONDS DAEMON DESCRIPTION COMMAND...: poll until COMMAND succeeds
    local limit=$1 daemon=$2 what=$3
    shift 3
    for ((i = 0; i < limit * 4; i++)); do
        # a client that cannot reach its daemon may retry for long: cut each try at 10 s
        if [[ $(type -t "$1") == function ]]; then
            "$@" >/dev/null 2>&1 && return 0
        elif timeout 10 "$@" >/dev/null 2>&1; then
            return 0
        fi
        if ! alive "$daemon"; then
            show_log "$daemon"
            die "$daemon exited before $what (logs: $STATE)"
        fi
        sleep 0.25
    done
    show_log "$daemon"
    die "no $what after $limit s (logs: $STATE)"
}

start() {  # start NAME COMMAND...: run in the background and record its PID
    local name=$1
    shift
    "$@" >>"$LOG/$name.out" 2>&1 &
    echo $! >"$PIDS/$name.pid"
}

install_packages() {
    local missing=()
    for cmd in slurmctld slurmd sbatch munged mariadbd slurmdbd; do
        command -v "$cmd" >/dev/null || missing+=("$cmd")
    done
    [[ ${#missing[@]} -eq 0 ]] && return 0
    [[ $(id -u) -eq 0 ]] || unavailable "missing ${missing[*]} and not root: cannot install ${PACKAGES[*]}"
    command -v apt-get >/dev/null || unavailable "missing ${missing[*]} and no apt-get to install ${PACKAGES[*]}"
    echo "cluster.sh: installing ${PACKAGES[*]} with apt-get" >&2
    DEBIAN_FRONTEND=noninteractive apt-get update -qq >&2
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${PACKAGES[@]}" >&2
}

write_configs() {
    local node db_password
    # the node line as slurmd itself sees this machine (CPUs, sockets, memory)
    node=$(slurmd -C | head -n 1)
    db_password=$(head -c 12 /dev/urandom | od -An -tx1 | tr -d ' \n')
    echo "$db_password" >"$ETC/db_password"
    cat >"$ETC/slurm.conf" <<EOF
ClusterName=$CLUSTER
SlurmctldHost=$(hostname -s)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
AuthType=auth/munge
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/slurmd
SlurmctldPidFile=$STATE/run/slurmctld.pid
SlurmdPidFile=$STATE/run/slurmd.pid
SlurmctldLogFile=$LOG/slurmctld.log
SlurmdLogFile=$LOG/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
ReturnToService=2
MailProg=/bin/true
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
# finished jobs stay visible to squeue for 5 min (sacct keeps them for good)
MinJobAge=300
KillWait=10
InactiveLimit=0
JobAcctGatherType=jobacct_gather/linux
JobAcctGatherFrequency=10
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=localhost
AccountingStoragePort=$DBD_PORT
AccountingStorageEnforce=associations,limits
JobCompType=jobcomp/none
# sacct shows the comment snakemake gives every job (its rule and wildcards)
AccountingStoreFlags=job_comment
$node State=UNKNOWN
PartitionName=$PARTITION Nodes=ALL Default=YES MaxTime=7-00:00:00 State=UP
EOF
    cat >"$ETC/slurmdbd.conf" <<EOF
AuthType=auth/munge
DbdHost=localhost
DbdPort=$DBD_PORT
SlurmUser=root
PidFile=$STATE/run/slurmdbd.pid
LogFile=$LOG/slurmdbd.log
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort=$DB_PORT
StorageUser=slurm
StoragePass=$db_password
StorageLoc=slurm_acct_db
EOF
    chmod 600 "$ETC/slurmdbd.conf" "$ETC/db_password"
}

munge_answers() { munge -n 2>/dev/null | unmunge >/dev/null 2>&1; }

sql() { mariadb --connect-timeout=5 --socket="$STATE/mysql/mysqld.sock" -uroot -e "$1"; }

up() {
    if alive slurmd && alive slurmctld && sinfo -h >/dev/null 2>&1; then
        echo "cluster.sh: already up in $STATE" >&2
        return 0
    fi
    for name in "${DAEMONS[@]}"; do
        alive "$name" && die "$name from an earlier start still runs in $STATE; run '$0 down $STATE' first"
    done
    install_packages
    [[ $(id -u) -eq 0 ]] || unavailable "not root: the daemons run as root, munge and mysql"
    [[ -r /etc/munge/munge.key ]] || unavailable "no /etc/munge/munge.key (the munge package creates it)"
    mkdir -p "$STATE" "$PIDS" "$ETC" "$LOG" "$STATE/run" "$STATE/ctld" "$STATE/slurmd" "$STATE/munge" "$STATE/mysql"
    # munge and mysql run as their own users and must reach their folders
    chmod 755 "$STATE"
    chown munge:munge "$STATE/munge"
    chown mysql:mysql "$STATE/mysql"
    # snakemake-executor-plugin-slurm-jobstep 0.6.1 drops SLURM_CONF from the environment
    # of the srun inside each job, so srun there needs slurm.conf at its default place, as
    # on a real site: a link to ours, removed by `down`; an existing slurm.conf is kept
    if [[ -e $SYSTEM_CONF || -L $SYSTEM_CONF ]] && [[ $(readlink "$SYSTEM_CONF") != "$ETC/slurm.conf" ]]; then
        die "$SYSTEM_CONF exists and is not this cluster's: not replacing a real SLURM configuration"
    fi
    trap 'status=$?; if [[ $status -ne 0 ]]; then echo "cluster.sh: start failed, stopping what was started" >&2; down; fi' EXIT
    write_configs
    mkdir -p "$(dirname "$SYSTEM_CONF")"
    ln -sfn "$ETC/slurm.conf" "$SYSTEM_CONF"

    # Slurm's clients reach munged at its default socket only (AuthInfo=socket= is not used
    # for the slurmdbd connection in 22.05); a munged already serving it is used, not started
    if ! munge_answers; then
        mkdir -p "$MUNGE_RUN"
        chown munge:munge "$MUNGE_RUN"
        start munged setpriv --reuid=munge --regid=munge --init-groups \
            munged --foreground --pid-file="$STATE/munge/munged.pid" \
            --seed-file="$STATE/munge/munged.seed" --log-file="$STATE/munge/munged.log"
        wait_for 20 munged "munge credential" munge_answers
    fi

    if [[ ! -d $STATE/mysql/mysql ]]; then
        mariadb-install-db --user=mysql --datadir="$STATE/mysql" --skip-test-db \
            --auth-root-authentication-method=socket >"$LOG/mariadb-install.log" 2>&1 \
            || { tail -n 20 "$LOG/mariadb-install.log" >&2; die "mariadb-install-db failed"; }
    fi
    start mariadbd mariadbd --user=mysql --datadir="$STATE/mysql" --socket="$STATE/mysql/mysqld.sock" \
        --port="$DB_PORT" --bind-address=127.0.0.1 --pid-file="$STATE/mysql/mariadbd.pid" \
        --log-error="$STATE/mysql/mariadbd.log" --skip-log-bin
    wait_for 60 mariadbd "MariaDB socket" sql "SELECT 1"
    local pw
    pw=$(<"$ETC/db_password")
    for host in localhost 127.0.0.1; do
        sql "CREATE USER IF NOT EXISTS 'slurm'@'$host' IDENTIFIED BY '$pw';
             ALTER USER 'slurm'@'$host' IDENTIFIED BY '$pw';
             GRANT ALL ON slurm_acct_db.* TO 'slurm'@'$host';"
    done

    start slurmdbd slurmdbd -D
    wait_for 60 slurmdbd "answer from slurmdbd" sacctmgr -n list cluster
    # idempotent: sacctmgr says "Nothing new added" for what exists
    sacctmgr -i add cluster "$CLUSTER" >/dev/null || true
    sacctmgr -i add account "$ACCOUNT" Cluster="$CLUSTER" Description="jamflow test" Organization=jamflow >/dev/null || true
    sacctmgr -i add user root Account="$ACCOUNT" Cluster="$CLUSTER" >/dev/null || true
    sacctmgr -i modify user root set DefaultAccount="$ACCOUNT" >/dev/null || true

    start slurmctld slurmctld -D
    wait_for 60 slurmctld "answer from slurmctld" scontrol ping
    start slurmd slurmd -D
    wait_for 60 slurmd "idle node" bash -c "sinfo -h -o %t | grep -q idle"
    trap - EXIT
    echo "cluster.sh: up in $STATE: $(sinfo -h -o '%P %D %t %c CPUs %m MB') (slurm $(slurmctld -V | cut -d' ' -f2))" >&2
}

down() {
    if alive slurmctld; then
        scancel --user="$(id -un)" >/dev/null 2>&1 || true
    fi
    local i name pid
    for ((i = ${#DAEMONS[@]} - 1; i >= 0; i--)); do
        name=${DAEMONS[i]}
        if alive "$name"; then
            pid=$(<"$PIDS/$name.pid")
            kill -TERM "$pid" 2>/dev/null || true
            for ((t = 0; t < 80; t++)); do
                alive "$name" || break
                sleep 0.25
            done
            if alive "$name"; then
                echo "cluster.sh: $name (PID $pid) ignored TERM for 20 s, killing it" >&2
                kill -KILL "$pid" 2>/dev/null || true
            fi
        fi
        rm -f "$PIDS/$name.pid"
    done
    if [[ -L $SYSTEM_CONF && $(readlink "$SYSTEM_CONF") == "$ETC/slurm.conf" ]]; then
        rm -f "$SYSTEM_CONF"
    fi
}

case $ACTION in
    up) up ;;
    down) down ;;
    env) echo "export SLURM_CONF=$SLURM_CONF" ;;
    *) usage ;;
esac
