#!/usr/bin/env bash
# Runs every test of the workspace on a fresh machine: installs what the tests
# need, then `cargo test` over all crates. Used by CI (.ci/run) and by people.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
# Packages some crates' tests need (kept in one place; see README).
for pkg in $(cat scripts/apt-packages.txt 2>/dev/null | grep -v '^#'); do
  dpkg -s "$pkg" >/dev/null 2>&1 || need_apt+=("$pkg")
done
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "installing: ${need_apt[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${need_apt[@]}"
fi

# The fleet link's acceptance test (fleet/tests/master.rs) runs a VDA 5050 master written
# with the npm package vda-5050-lib: Node.js, npm, and the packages of
# fleet/master/package-lock.json, installed with `npm ci` when node_modules is missing or
# was installed from another lock file (node_modules/.wlnav-lock, as the test checks it).
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  echo "installing: nodejs npm (fleet/master)"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends nodejs npm
fi
if ! cmp -s fleet/master/package-lock.json fleet/master/node_modules/.wlnav-lock; then
  npm ci --prefix fleet/master --no-audit --no-fund --loglevel=error
  cp fleet/master/package-lock.json fleet/master/node_modules/.wlnav-lock
fi

cargo test --workspace --locked "$@"

# The committed weights (one directory per machine) must open in Python's
# safetensors too (issue 3).
machines=(critic-weights/*/critic.safetensors)
if [ -f "${machines[0]}" ]; then
  venv=target/python-check
  [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
  "$venv/bin/python" -c "import safetensors, numpy" 2>/dev/null ||
    "$venv/bin/pip" install -q safetensors numpy
  for critic in "${machines[@]}"; do
    "$venv/bin/python" scripts/check_weights_python.py "$(dirname "$critic")"
  done
fi

# The programs of examples/ against a running daemon (issue 17).
bash scripts/examples.sh

# The Debian package builds, installs, verifies and removes cleanly (issue 18); it
# packages the binaries `cargo test --workspace` just built, so only on a full run.
if [ $# -eq 0 ]; then
  bash scripts/package-check.sh
else
  echo "test.sh: package check skipped (cargo test was given arguments: $*)"
fi

# The Jetson's build (issue 28): arm64 binaries, the control, shm-ipc, daemon and e2e
# tests under qemu, the examples against an arm64 daemon, the arm64 package. Opt-in
# (WLNAV_CROSS_CHECK=1): it does not fit CI's budget (at most 45 min; the test command
# takes 27-35 min without it). Measured 2026-12-03 (README, "The Jetson"): the arm64 build
# from scratch is 1723 s user + 50 s sys of CPU (>= 14.8 min on two free cores), its tests
# under qemu about 12 min, the examples and the package 40 s: about 27 min where about 18
# are left. Any failure in it is fatal.
if [ $# -eq 0 ] && [ "${WLNAV_CROSS_CHECK:-0}" = 1 ]; then
  bash scripts/cross-check.sh
else
  echo "test.sh: cross check not run (opt-in: WLNAV_CROSS_CHECK=1 and no arguments run it, about 27 min more on two free cores)"
fi
