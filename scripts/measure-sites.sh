#!/usr/bin/env bash
# The sites of issue 40 measured (docs/results.md §5): wlnav-sim eval on each site's goal
# set (sim/scenarios/site-*.csv) in its site (sim/sites/*.json), with the default outline
# (MPC and the min-time bound T*) and the Avant 635's truer outline (MPC; t / T* against the
# default outline's bound, a lower bound for it too: its circles cover the default's axle
# discs, control::site::outline tests). About 12 min on 2 free cores.
#   scripts/measure-sites.sh [OUT]     # OUT: target/sites; then python3 scripts/sites_table.py OUT
set -uo pipefail
cd "$(dirname "$0")/.."
echo "commit $(git rev-parse --short HEAD) start $(date -u +%FT%TZ)"
cargo build --release -p sim --bin wlnav-sim || exit 1
S=target/release/wlnav-sim
O=${1:-target/sites}; rm -rf "$O"; mkdir -p "$O"
COMMON="--no-scenario-plots --jobs 2 --time-budget 1 --duration 90"
failed=0
for site in quarry yard lane large-pit-40; do
  sc=sim/scenarios/site-$site.csv
  st=sim/sites/$site.json
  t0=$(date +%s)
  # The bound first, on its own: IPOPT runs one solve at a time in a process (MUMPS is not
  # thread-safe), so a bound solved beside the MPC runs would hold their trajectory solves
  # for seconds and the plan times would measure the wait. Its rows are then appended to
  # the MPC's, one file per site and outline as before.
  $S eval $COMMON --methods min-time --scenarios "$sc" --site "$st" --outline axle-circles \
    --out "$O/$site-bound" > "$O/$site-bound.log" 2>&1 || failed=1
  $S eval $COMMON --methods mpc --scenarios "$sc" --site "$st" --outline axle-circles \
    --t-star "$O/$site-bound/results.csv" --out "$O/$site-axle-circles" > "$O/$site-axle-circles.log" 2>&1 || failed=1
  tail -n +2 "$O/$site-bound/results.csv" >> "$O/$site-axle-circles/results.csv"
  $S eval $COMMON --methods mpc --scenarios "$sc" --site "$st" --outline avant635 \
    --t-star "$O/$site-bound/results.csv" --out "$O/$site-avant635" > "$O/$site-avant635.log" 2>&1 || failed=1
  echo "$site: $(($(date +%s) - t0)) s"
done
# The large pit's tick alone on the machine (one run at a time): the figure of the
# issue's scale target (tick median <= 2 ms, p99 <= 10 ms).
for outline in axle-circles avant635; do
  $S eval --no-scenario-plots --jobs 1 --time-budget 1 --duration 90 --methods mpc \
    --scenarios sim/scenarios/site-large-pit-40.csv --site sim/sites/large-pit-40.json \
    --outline $outline --t-star "$O/large-pit-40-axle-circles/results.csv" \
    --out "$O/pit-alone-$outline" > "$O/pit-alone-$outline.log" 2>&1 || failed=1
done
echo "done $(date -u +%FT%TZ)"
[ $failed -eq 0 ] || { echo "measure-sites: a run FAILED (see the logs in $O)" >&2; exit 1; }
