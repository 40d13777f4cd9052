#!/usr/bin/env bash
# Runs every test of the workspace on a fresh machine: installs what the tests
# need, then `cargo test` over all crates. Used by CI (.ci/run) and by people.
set -euo pipefail
cd "$(dirname "$0")/.."
# Every "§" reference resolves to a heading of docs/design.md, every docs link to a file (1 s, no build).
bash scripts/check-design-refs.sh

# Each phase's wall time and CPU time (user + sys of its processes, which a loaded machine
# does not inflate), listed at the end: what the command costs on two free cores follows
# from them (docs/guide/testing.md, "What a full run costs").
phase_times=()
cpu_now() {
  times >target/.test-times
  read -r cpu_user cpu_sys < <(tail -n 1 target/.test-times | sed 's/[ms]/ /g' |
    awk '{ printf "%.1f %.1f\n", $1 * 60 + $2, $3 * 60 + $4 }')
}
phase() {
  local name=$1 t0 u0 s0
  shift
  t0=$(date +%s)
  cpu_now
  u0=$cpu_user s0=$cpu_sys
  running_phase=$name running_t0=$t0
  "$@"
  running_phase=
  cpu_now
  phase_times+=("$name: $(($(date +%s) - t0)) s wall, $(awk -v u="$cpu_user" -v s="$cpu_sys" \
    -v u0="$u0" -v s0="$s0" 'BEGIN { printf "%.0f s user + %.0f s sys", u - u0, s - s0 }') of CPU")
}
mkdir -p target
# The list is printed however the command ends (a failure too: its cost is then known).
running_phase=
print_phases() {
  echo "test.sh: time per phase:"
  [ ${#phase_times[@]} -eq 0 ] || printf '  %s\n' "${phase_times[@]}"
  if [ -n "$running_phase" ]; then
    echo "  $running_phase: did not finish ($(($(date +%s) - running_t0)) s wall)"
  fi
}
cross_build=
on_exit() {
  if [ -n "$cross_build" ]; then kill -- -"$cross_build" 2>/dev/null || true; fi
  print_phases
}
trap on_exit EXIT

need_apt=()
# Packages some crates' tests need (kept in one place; see docs/guide/testing.md).
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

# The Jetson's build (issue 28): arm64 binaries, the control, shm-ipc, daemon and e2e
# tests under qemu, the examples against an arm64 daemon, the arm64 package
# (scripts/cross-check.sh). On every full run (no arguments); WLNAV_SKIP_CROSS_CHECK=1
# skips it (a workstation without root, as WLNAV_SKIP_PACKAGE_CHECK). Its
# packages are installed first (apt, before the package check snapshots the system); its
# arm64 build then runs in the background at the lowest priority, on what the native build
# and tests leave of the cores (they wait on their daemons much of the time), and its tests
# under qemu run after the package check. Any failure in it is fatal.
cross=0
if [ $# -eq 0 ] && [ "${WLNAV_SKIP_CROSS_CHECK:-0}" != 1 ]; then
  cross=1
  phase "arm64 toolchain (cross-check.sh setup)" bash scripts/cross-check.sh setup
  # SCHED_IDLE (chrt --idle): it runs only on a core nothing else wants, so the native
  # build and tests go as fast as without it and the tests' timings see the same machine.
  # Its own process group, so that a failure here stops the whole build (trap below), but
  # in this session: `set -m` (job control), not setsid. A new session is a new scheduler
  # autogroup (kernel.sched_autogroup_enabled, on by default), and autogroups share the
  # CPU evenly whatever the priorities inside them: measured, a setsid'd SCHED_IDLE loop
  # took as much CPU as two normal ones together; in the same session, almost none.
  idle=(chrt --idle 0)
  "${idle[@]}" true 2>/dev/null || idle=(nice -n 19)
  set -m
  "${idle[@]}" bash scripts/cross-check.sh build >target/cross-check-build.log 2>&1 &
  cross_build=$!
  set +m
fi

# The build first, then the tests (same selection: nothing is built twice), so that each
# has its own time.
phase "native test build (cargo test --no-run)" cargo test --workspace --locked --no-run "$@"
phase "native tests (cargo test)" cargo test --workspace --locked "$@"

# The committed weights (one directory per machine) must open in Python's
# safetensors too (issue 3).
check_weights() {
  local machines=(critic-weights/*/critic.safetensors) venv=target/python-check critic
  [ -f "${machines[0]}" ] || return 0
  [ -x "$venv/bin/python" ] || python3 -m venv "$venv"
  "$venv/bin/python" -c "import safetensors, numpy" 2>/dev/null ||
    "$venv/bin/pip" install -q safetensors numpy
  for critic in "${machines[@]}"; do
    "$venv/bin/python" scripts/check_weights_python.py "$(dirname "$critic")"
  done
}
phase "weights in Python" check_weights

# The programs of examples/ against a running daemon (issue 17).
phase "examples" bash scripts/examples.sh

# The Debian package builds, installs, verifies and removes cleanly (issue 18); it
# packages the binaries `cargo test --workspace` just built, so only on a full run.
if [ $# -eq 0 ]; then
  phase "package check" bash scripts/package-check.sh
else
  echo "test.sh: package check skipped (cargo test was given arguments: $*)"
fi

# The cross check's tests (docs/guide/deployment.md, "The Jetson"), once its build is done.
wait_for_cross_build() {
  # The native part is done: what is left of the arm64 build runs at normal priority (at
  # idle priority it would wait for anything else on the machine; the rustc processes
  # cargo starts from now on inherit its policy).
  local p
  for p in $(pgrep -g "$cross_build" 2>/dev/null); do
    chrt --other -a -p 0 "$p" 2>/dev/null || true
    renice -n 0 -p "$p" >/dev/null 2>&1 || true
  done
  if ! wait $cross_build; then
    tail -n 40 target/cross-check-build.log >&2
    echo "test.sh: the arm64 build failed (target/cross-check-build.log)" >&2
    exit 1
  fi
}
if [ $cross = 1 ]; then
  phase "arm64 build, waited for (its CPU: the whole build, run in the background)" wait_for_cross_build
  cross_build=
  cat target/cross-check-build.log
  phase "arm64 tests under qemu, examples, package (cross-check.sh run)" bash scripts/cross-check.sh run
else
  echo "test.sh: arm64 check not run (WLNAV_SKIP_CROSS_CHECK=1, or cargo test was given arguments)"
fi
echo "test.sh: passed"
