#!/usr/bin/env bash
# Runs each program of examples/ against its own `wlnavd --sim` (its own prefix) and fails,
# with the daemon's log, if one does not exit 0. Called by scripts/test.sh (CI).
set -euo pipefail
cd "$(dirname "$0")/.."

# The binaries of the test build (`cargo test --workspace` builds wlnavd and the examples,
# which have integration tests): the same selection, so nothing is rebuilt when the tests
# just ran; the dev profile is fast enough for a 5 Hz loop.
# WLNAV_EXAMPLES_BIN_DIR: prebuilt wlnavd, goal-client, pose-publisher and person-publisher from elsewhere
# (scripts/cross-check.sh: the arm64 ones, run under qemu).
if [ -n "${WLNAV_EXAMPLES_BIN_DIR:-}" ]; then
  bin=$WLNAV_EXAMPLES_BIN_DIR
else
  cargo test --workspace --locked --no-run -q
  bin=target/debug
fi
venv=target/python-examples
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/pip" install -q -r examples/requirements.txt

# WLNAV_TIMING_SCALE > 1 (a slower CPU; the arm64 binaries under qemu, scripts/cross-check.sh):
# the daemon's solver budget, wlnavd's default mpc.time_budget of 0.1 s (also its start-up
# self-test's), times that factor, in a copy of the example's configuration (weights
# paths made absolute, as the copy lives in target/); each example's 180-s limit here
# times it too, as the examples' own timeouts are (they read WLNAV_TIMING_SCALE).
scale=${WLNAV_TIMING_SCALE:-1}
budget_config() {
  local name=$1 config=$2 out=target/example-$1.toml
  if [ -n "$config" ]; then
    sed "s#\"\.\./#\"$PWD/#" "$config" > "$out"
  else
    : > "$out"
  fi
  printf '\n[mpc]\ntime_budget = %s\n' "$(python3 -c "print(0.1 * float('$scale'))")" >> "$out"
  echo "$out"
}

run() {
  local name=$1 config=$2
  shift 2
  if [ "$scale" != 1 ]; then
    config=$(budget_config "$name" "$config")
  fi
  local prefix="wlnav-example-$name-$$" log="target/example-$name.log"
  local args=(--sim --prefix "$prefix")
  [ -n "$config" ] && args+=(--config "$config")
  "$bin/wlnavd" "${args[@]}" >"$log" 2>&1 &
  local daemon=$!
  echo "example $name: $* --prefix $prefix"
  if ! timeout "$(python3 -c "print(round(180 * float('$scale')))")" "$@" --prefix "$prefix"; then
    echo "example $name FAILED; wlnavd log:" >&2
    tail -n 40 "$log" >&2
    kill "$daemon" 2>/dev/null || true
    exit 1
  fi
  kill -TERM "$daemon"
  wait "$daemon" || { echo "example $name: wlnavd did not exit cleanly" >&2; tail -n 20 "$log" >&2; exit 1; }
}

run goal-client "" "$bin/goal-client"
run pose-publisher examples/external-pose.toml "$bin/pose-publisher"
run python-client "" "$venv/bin/python" examples/python_client.py
run person-publisher examples/external-perception.toml "$bin/person-publisher"
run python-obstacles examples/external-perception.toml "$venv/bin/python" examples/python_obstacles.py
echo "examples: all five exit 0"
