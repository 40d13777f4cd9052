#!/usr/bin/env bash
# Deadline benchmark (issue 18): wlnavd on its simulated machine in real time (200 ms
# ticks on absolute deadlines, time scale 1), driving goals the whole run, optionally
# beside CPU-bound processes and with the tick thread real-time ([loop.realtime]).
# Prints wlnavd's loop statistics: tick start lateness against the absolute deadline
# (median, p99, max), overruns, missed deadlines, MPC solve time.
#
#   scripts/deadline-bench.sh [--ticks N] [--realtime on|off] [--hogs K] [--cpu C] [--out DIR]
#
# Defaults: 3000 ticks (10 minutes), realtime off, no hogs. The hogs are `yes > /dev/null`
# at normal priority, started before and killed after the run. Needs the release build:
#   cargo build --release -p daemon -p wlnav-cli
# SCHED_FIFO needs root or RLIMIT_RTPRIO >= the priority (see README, Field installation).
set -euo pipefail
cd "$(dirname "$0")/.."

ticks=3000
realtime=off
hogs=0
cpu=
out=target/deadline-bench
while [ $# -gt 0 ]; do
  case "$1" in
    --ticks) ticks=$2; shift 2 ;;
    --realtime) realtime=$2; shift 2 ;;
    --hogs) hogs=$2; shift 2 ;;
    --cpu) cpu=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    *) echo "deadline-bench: unknown argument $1" >&2; exit 2 ;;
  esac
done
case "$realtime" in on|off) ;; *) echo "deadline-bench: --realtime on|off" >&2; exit 2 ;; esac

wlnavd=${WLNAVD:-target/release/wlnavd}
wlnav=${WLNAV:-target/release/wlnav}
for b in "$wlnavd" "$wlnav"; do
  [ -x "$b" ] || { echo "deadline-bench: $b missing (cargo build --release -p daemon -p wlnav-cli)" >&2; exit 2; }
done

mkdir -p "$out"
name="rt-$realtime-hogs-$hogs"
config="$out/$name.toml"
{
  echo "# written by scripts/deadline-bench.sh"
  echo "[loop.realtime]"
  [ "$realtime" = on ] && echo "enabled = true" || echo "enabled = false"
  [ -n "$cpu" ] && echo "cpu = $cpu"
} > "$config"
prefix="bench-$$"

hog_pids=()
daemon_pid=
cleanup() {
  for p in "${hog_pids[@]}"; do kill "$p" 2>/dev/null || true; done
  [ -n "$daemon_pid" ] && kill "$daemon_pid" 2>/dev/null || true
}
trap cleanup EXIT

for _ in $(seq 1 "$hogs"); do
  yes > /dev/null &
  hog_pids+=($!)
done

echo "deadline-bench: $ticks ticks, realtime $realtime, $hogs CPU hog(s)${cpu:+, tick thread on CPU $cpu}"
echo "  started $(date -u +%FT%TZ), load average $(cut -d' ' -f1-3 /proc/loadavg), $(nproc) CPUs"
"$wlnavd" --sim --config "$config" --prefix "$prefix" --max-ticks "$ticks" --log terminal \
  > "$out/$name.summary" 2> "$out/$name.log" &
daemon_pid=$!

# Goals the whole run: the demo's loading cycle (pile face, back out turning, dump
# point), a new goal every 10 s (each leg takes 7-8 s), so the MPC solves on most ticks.
goals=("5 0 0" "1.5 1.5 -60" "4 -2.83 -60")
i=0
next=$(date +%s)
while kill -0 "$daemon_pid" 2>/dev/null; do
  if [ "$(date +%s)" -ge "$next" ]; then
    # Rejected (daemon not ready yet) or no reply: try again in 0.5 s.
    # shellcheck disable=SC2086
    if "$wlnav" --prefix "$prefix" goal ${goals[$((i % 3))]} --deg >/dev/null 2>&1; then
      i=$((i + 1))
      next=$(($(date +%s) + 10))
    fi
  fi
  sleep 0.5
done
status=0
wait "$daemon_pid" || status=$?
daemon_pid=
echo "  ended   $(date -u +%FT%TZ), load average $(cut -d' ' -f1-3 /proc/loadavg), $i goals sent"
grep -h 'real-time' "$out/$name.log" | sed 's/^.*real-time/  real-time/' || true
sed 's/^/  /' "$out/$name.summary"
[ "$status" -eq 0 ] || { echo "deadline-bench: wlnavd exited with $status (log: $out/$name.log)" >&2; exit 1; }
