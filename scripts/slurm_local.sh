#!/usr/bin/env bash
# A one-node Slurm on this machine, for testing scripts/slurm_bench.sh for real (CI runs it).
#
#   scripts/slurm_local.sh start    # install (Debian: slurm-wlm, munge) if missing, configure, start
#   scripts/slurm_local.sh status   # exit 0 when the node answers and is idle or mixed
#   scripts/slurm_local.sh stop     # stop the daemons this script started
#
# Needs root (it writes /etc/slurm/slurm.conf and starts munged, slurmctld and slurmd). The node
# is this host with all its cores and 90% of its memory, one partition `debug`; no cgroups, no
# accounting, so it starts inside containers. An existing /etc/slurm/slurm.conf that this script
# did not write is left alone and the script refuses to start (it never replaces a real
# cluster's configuration).
set -euo pipefail

conf=/etc/slurm/slurm.conf
state=/var/lib/marchmesh-slurm
marker="# written by marchmesh scripts/slurm_local.sh"

die() { echo "error: $*" >&2; exit 1; }

# Whether a live process is named $1 (zombies left by a killed daemon do not count).
running() { ps -C "$1" -o stat= 2>/dev/null | grep -qv '^Z'; }

need_root() { [ "$(id -u)" = 0 ] || die "run as root (it configures and starts slurmctld, slurmd and munged)"; }

install() {
  if command -v slurmctld >/dev/null && command -v slurmd >/dev/null \
    && command -v sbatch >/dev/null && command -v munged >/dev/null; then
    return
  fi
  command -v apt-get >/dev/null || die "Slurm is not installed and apt-get is not available to install it"
  export DEBIAN_FRONTEND=noninteractive
  apt-get install -y --no-install-recommends slurm-wlm munge >/dev/null 2>&1 \
    || { apt-get update >/dev/null && apt-get install -y --no-install-recommends slurm-wlm munge >/dev/null; }
  apt-get clean >/dev/null 2>&1 || true
}

write_conf() {
  if [ -f "$conf" ] && ! grep -qF "$marker" "$conf"; then
    die "$conf exists and was not written by this script; not touching a real cluster's configuration"
  fi
  local host cpus mem
  host=$(hostname -s)
  cpus=$(nproc)
  mem=$(awk '/MemTotal/ { printf "%d", $2 / 1024 * 0.9 }' /proc/meminfo)
  mkdir -p /etc/slurm "$state/ctld" "$state/d" /var/log/slurm
  cat >"$conf" <<EOF
$marker
ClusterName=marchmesh
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/d
SlurmctldPidFile=$state/slurmctld.pid
SlurmdPidFile=$state/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=300
KillWait=5
Waittime=0
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
  # Debian's slurm reads cgroup.conf only with cgroup plugins; none are configured.
}

start_munge() {
  if running munged && [ -S /run/munge/munge.socket.2 ]; then return; fi
  pkill -x munged 2>/dev/null || true
  for _ in $(seq 1 50); do running munged || break; sleep 0.1; done
  mkdir -p /etc/munge /run/munge /var/log/munge /var/lib/munge
  if [ ! -s /etc/munge/munge.key ]; then
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1 count=1024 status=none
  fi
  local user=root
  id munge >/dev/null 2>&1 && user=munge
  chown "$user" /etc/munge /etc/munge/munge.key /run/munge /var/log/munge /var/lib/munge
  chmod 0700 /etc/munge /var/log/munge /var/lib/munge
  chmod 0400 /etc/munge/munge.key
  chmod 0755 /run/munge
  if [ "$user" = root ]; then
    munged --force
  else
    runuser -u munge -- munged
  fi
  for _ in $(seq 1 100); do [ -S /run/munge/munge.socket.2 ] && return; sleep 0.1; done
  die "munged did not open /run/munge/munge.socket.2 within 10 s"
}

node_ready() {
  local s
  s=$(sinfo -h -N -o '%T' 2>/dev/null | head -1) || return 1
  case $s in (idle|mixed|allocated|completing) return 0;; (*) return 1;; esac
}

start() {
  need_root
  install
  write_conf
  start_munge
  # -c: a fresh controller state (this is a test cluster; jobs of an earlier run are gone).
  running slurmctld || slurmctld -c
  running slurmd || slurmd
  for _ in $(seq 1 60); do
    if node_ready; then
      echo "slurm: node $(hostname -s) is up ($(nproc) cores, partition debug)"
      return 0
    fi
    sleep 1
  done
  echo "--- slurmctld.log" >&2; tail -20 /var/log/slurm/slurmctld.log >&2 2>/dev/null || true
  echo "--- slurmd.log" >&2; tail -20 /var/log/slurm/slurmd.log >&2 2>/dev/null || true
  die "the Slurm node did not come up within 60 s"
}

stop() {
  need_root
  pkill -x slurmd 2>/dev/null || true
  pkill -x slurmctld 2>/dev/null || true
  for _ in $(seq 1 100); do
    running slurmd || running slurmctld || return 0
    sleep 0.1
  done
}

case ${1:-} in
  start) start ;;
  stop) stop ;;
  status) node_ready ;;
  *) echo "usage: $0 start|stop|status" >&2; exit 2 ;;
esac
