#!/usr/bin/env bash
# The sites of issue 40 measured (docs/results-sites.md): wlnav-sim eval on each site's goal
# set (sim/scenarios/site-*.csv) in its site (sim/sites/*.json), with the default outline
# (MPC and the min-time bound T*) and the Avant 635's truer outline (MPC; t / T* against the
# default outline's bound, a lower bound for it too: its circles cover the default's axle
# discs, control::site::outline tests). About 10 min on 2 free cores.
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
  $S eval $COMMON --methods mpc,min-time --scenarios "$sc" --site "$st" --outline axle-circles \
    --out "$O/$site-axle-circles" > "$O/$site-axle-circles.log" 2>&1 || failed=1
  $S eval $COMMON --methods mpc --scenarios "$sc" --site "$st" --outline avant635 \
    --t-star "$O/$site-axle-circles/results.csv" --out "$O/$site-avant635" > "$O/$site-avant635.log" 2>&1 || failed=1
  echo "$site: $(($(date +%s) - t0)) s"
done
echo "done $(date -u +%FT%TZ)"
[ $failed -eq 0 ] || { echo "measure-sites: a run FAILED (see the logs in $O)" >&2; exit 1; }
