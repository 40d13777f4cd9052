#!/usr/bin/env bash
# Things that move measured (issue 41, DESIGN §18; docs/movers.md): wlnav-sim eval (MPC, the
# daemon's defaults) on open ground (the paper's 128) and on the sites of issue 40 (quarry,
# yard, lane, large-pit-40: their goal sets sim/scenarios/site-*.csv, 90 s a goal as
# measure-sites.sh), each without movers and with each of its mover files (sim/movers/*.csv,
# sim/movers/sites/<site>/*.csv, written by scripts/make_movers.py; a site file with no mover
# is skipped), the simulated perception at 10 Hz with 5 % of its sets lost, in three cases:
#   lat0.1        latency 0.1 s, the live settings' defaults (the issue's acceptance)
#   lat0.3        latency 0.3 s, the defaults
#   lat0.3-large  latency 0.3 s, larger fields: --live $LARGE (default stop_margin=0.8)
# Then the open-ground truck once more with 60 s a goal (below). About 20 min on 2 free cores
# (one eval at a time, --jobs 2).
#   scripts/measure-movers.sh [OUT]    # OUT: target/movers; then
#   python3 scripts/movers_table.py OUT COMMIT
# CASES="lat0.1" scripts/measure-movers.sh runs only the first case.
set -uo pipefail
cd "$(dirname "$0")/.."
echo "commit $(git rev-parse --short HEAD) start $(date -u +%FT%TZ)"
cargo build --release -p sim --bin wlnav-sim || exit 1
S=target/release/wlnav-sim
O=${1:-target/movers}; rm -rf "$O"; mkdir -p "$O"
CASES=${CASES:-"lat0.1 lat0.3 lat0.3-large"}
LARGE=${LARGE:-stop_margin=0.8}
echo "cases: $CASES; larger fields: $LARGE" | tee "$O/cases.txt"
COMMON="--no-scenario-plots --jobs 2 --time-budget 1 --methods mpc"
failed=0
run() { # name, then eval's arguments
  local name=$1; shift
  local t0=$(date +%s)
  if ! $S eval $COMMON "$@" --out "$O/$name" > "$O/$name.log" 2>&1 || [ ! -s "$O/$name/results.csv" ]; then
    echo "FAILED: $name (see $O/$name.log)" >&2; failed=1
  fi
  echo "$name: $(($(date +%s) - t0)) s"
}
case_args() {
  case $1 in
    lat0.1) echo "--perception-latency 0.1 --perception-rate 10 --perception-dropout 0.05" ;;
    lat0.3) echo "--perception-latency 0.3 --perception-rate 10 --perception-dropout 0.05" ;;
    lat0.3-large) echo "--perception-latency 0.3 --perception-rate 10 --perception-dropout 0.05 --live $LARGE" ;;
    *) echo "unknown case $1" >&2; exit 1 ;;
  esac
}
# Open ground.
OPEN="--scenarios sim/scenarios/paper128.csv --t-star docs/results/paper128.csv"
run open-none $OPEN
for c in $CASES; do
  for f in sim/movers/*.csv; do
    # The demo's person and the crowd (for the tick's time) are not the mover set.
    case $(basename "$f") in demo.csv|crowd128.csv) continue ;; esac
    run "open-$(basename "$f" .csv)-$c" $OPEN --movers "$f" $(case_args $c)
  done
done
# The truck on open ground again with 60 s a goal instead of the paper's 30: whether the goals
# it leaves unreached are only late (it parks on the way for 10 s).
for c in $CASES; do
  run "open-truck-reversing-$c-d60" $OPEN --movers sim/movers/truck-reversing.csv $(case_args $c) --duration 60
done
# The sites.
for site in quarry yard lane large-pit-40; do
  SITE="--scenarios sim/scenarios/site-$site.csv --site sim/sites/$site.json --duration 90"
  SITE="$SITE --t-star docs/results/sites/$site-axle-circles.csv"
  run "$site-none" $SITE
  for c in $CASES; do
    for f in sim/movers/sites/$site/*.csv; do
      if [ "$(grep -vc -e '^#' -e '^id,' -e '^$' "$f")" -eq 0 ]; then
        echo "$site: $(basename "$f") has no mover: skipped"; continue
      fi
      run "$site-$(basename "$f" .csv)-$c" $SITE --movers "$f" $(case_args $c)
    done
  done
done
echo "done $(date -u +%FT%TZ)"
[ $failed -eq 0 ] || { echo "measure-movers: a run FAILED (see the logs in $O)" >&2; exit 1; }
