#!/usr/bin/env bash
# Issue 26's acceptance runs (README "The safety envelope"): obstacles200 under every
# horizon x Hessian x obstacle-row form, and the two robustness cases that went inside a
# circle before, with their tolerances stated. Writes docs/envelope/NAME.csv and
# NAME.summary.txt; a setting whose output exists is skipped (rerun to continue).
# About 1 min per N = 10 setting, 2 per N = 20, 10-25 per N = 40 on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -p sim --bin wlnav-sim
out=docs/envelope
mkdir -p "$out"
run() {
  local name=$1; shift
  [ -f "$out/$name.csv" ] && return
  local tmp; tmp=$(mktemp -d)
  target/release/wlnav-sim eval --scenarios sim/scenarios/obstacles200.csv --methods mpc \
    --no-scenario-plots --t-star docs/results/worksite.csv --out "$tmp" "$@" | tee "$tmp/log"
  grep -E "^(# eval|methods|\| mpc|timing|navigation|envelope:|obstacle rows|clearance:)" "$tmp/log" \
    > "$out/$name.summary.txt"
  cp "$tmp/results.csv" "$out/$name.csv"
  rm -rf "$tmp"
}
run lr11 --plant-scale-lr 1.1 --geometry-tolerance 0.06
run moderate --plant-scale-lf 1.05 --plant-scale-lr 1.05 --plant-delay 0.25 --delay 0.2 \
  --actuator-gain 0.9 --pose-noise 0.02,0.01 --pose-latency 0.05 \
  --geometry-tolerance 0.06 --pose-noise-tolerance 0.02,0.01 --response-lag 0.05
for n in 10 20 40; do for h in exact gauss-newton; do for r in distance cbf; do
  run "n$n-$h-$r" --horizon "$n" --hessian "$h" --obstacles "$r"
done; done; done
