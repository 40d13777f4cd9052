#!/usr/bin/env bash
# The shipped envelope tolerances measured (issue 43; docs/envelope-tolerances.md, "What the
# shipped tolerances cost"): wlnav-sim eval on obstacles200 and the paper 128 with the
# shipped defaults, the exact envelope and the perturbed plants, then the robustness matrix
# with the shipped defaults (docs/robustness-shipped.md). About 10 min on 2 free cores.
#   scripts/measure-envelope-tolerances.sh [OUT]   # OUT: target/envelope-tolerances
set -uo pipefail
cd "$(dirname "$0")/.."
echo "commit $(git rev-parse --short HEAD) start $(date -u +%FT%TZ)"
cargo build --release -p sim --bin wlnav-sim || exit 1
S=target/release/wlnav-sim
O=${1:-target/envelope-tolerances}; rm -rf "$O"; mkdir -p "$O"
OBS="--scenarios sim/scenarios/obstacles200.csv --t-star docs/results/worksite.csv"
PAP="--scenarios sim/scenarios/paper128.csv --t-star docs/results/paper128.csv"
COMMON="--methods mpc --no-scenario-plots --jobs 2 --time-budget 1"
MOD="--delay 0.2 --plant-scale-lf 1.05 --plant-scale-lr 1.05 --plant-delay 0.25 --actuator-gain 0.9 --pose-noise 0.02,0.01 --pose-latency 0.05"
failed=0
run() {
  local name=$1 t0 rc
  shift
  t0=$(date +%s)
  echo "== $name: eval $COMMON $*"
  $S eval $COMMON "$@" --out "$O/$name" >"$O/$name.log" 2>&1
  rc=$?
  echo "   rc=$rc $(($(date +%s) - t0)) s (log: $O/$name.log)"
  [ $rc -eq 0 ] || failed=1
}
for k in 0 1 2; do
  w=$(python3 -c "print(f'{1000+1e-6*$k:.6f}')")
  run shipped-ideal-obs-k$k $OBS --obstacle-slack-weight $w
  run exact-ideal-obs-k$k $OBS --obstacle-slack-weight $w --exact-envelope
done
run shipped-ideal-paper $PAP
run exact-ideal-paper $PAP --exact-envelope
run shipped-moderate-obs $OBS $MOD
run shipped-moderate-paper $PAP $MOD
run shipped-pd08-obs $OBS --delay 0.2 --plant-delay 0.8
run shipped-pd08nc-obs $OBS --plant-delay 0.8
run shipped-pd08-paper $PAP --delay 0.2 --plant-delay 0.8
run shipped-lr11-obs $OBS --plant-scale-lr 1.1
run shipped-lr12-obs $OBS --plant-scale-lr 1.2
run shipped-lr12stop-obs $OBS --plant-scale-lr 1.2 --assumption-action stop
run shipped-noise3-obs $OBS --pose-noise 0.03,0.02
run shipped-gain14-obs $OBS --actuator-gain 1.4
rm -rf docs/robustness-shipped/cases
t0=$(date +%s)
echo "== robustness-shipped"
$S robustness --obstacles-per-kind 0 --shipped-envelope --name robustness-shipped --out docs --jobs 2 > $O/robustness.log 2>&1
rc=$?
echo "   rc=$rc $(($(date +%s) - t0)) s"
[ $rc -eq 0 ] || failed=1
echo "done $(date -u +%FT%TZ)"
[ $failed -eq 0 ] || { echo "measure-envelope-tolerances: a run FAILED (see the logs above)" >&2; exit 1; }
