#!/usr/bin/env bash
# Cross check for the Jetson AGX Orin (issue 28), run by scripts/test.sh (its tests after
# the package check): builds the deployable crates and the test suites for aarch64-unknown-linux-gnu
# with Debian's own Rust (no rustup target), runs the control, shm-ipc, daemon and
# end-to-end tests under qemu-aarch64-static, runs the programs of examples/ against an
# arm64 `wlnavd --sim`, builds the arm64 Debian package and checks it against the amd64
# one, and runs the packaged arm64 `wlnavd --check-config` on the packaged configuration
# and weights.
#
# Timing assertions of the tests are multiplied by WLNAV_TIMING_SCALE (set here to
# $CROSS_TIMING_SCALE, the one documented factor for emulation; tests/timing_scale.rs,
# README "The Jetson"): no test is skipped because of emulation.
#
# Everything arm64 is built once, in the profile `cross` (Cargo.toml: the workspace's crates
# at opt-level 3, other dependencies at 1, host-only crates at 0, one codegen unit, debug
# assertions on, no debug info), test executables and binaries with one feature set (step
# 3); the test executables then run directly under qemu. The package is checked, not shipped
# (README, "The Jetson"). The build goes to target/cross (Debian's rustc 1.96 is not the
# workspace's toolchain, so nothing would be shared with target/, and builds of both never
# wait for each other's lock; WLNAV_CROSS_TARGET_DIR moves it). Needs root (apt-get,
# binfmt_misc). WLNAV_SKIP_CROSS_CHECK=1 skips it. Each step prints its time in seconds.
#
# Phases: `cross-check.sh` runs all three; scripts/test.sh runs them apart, so that the
# arm64 build uses what the native tests leave of the two cores:
#   setup  installs the packages (apt; before anything else touches the package database)
#   build  builds everything arm64 (no root, no apt: may run in the background)
#   run    registers binfmt, runs the suites under qemu, the examples and the package check
set -euo pipefail
cd "$(dirname "$0")/.."
phases=${1:-all}
case $phases in
  setup | build | run) ;;
  all) phases="setup build run" ;;
  *) echo "usage: $0 [setup|build|run|all]" >&2; exit 2 ;;
esac
has_phase() { [[ " $phases " == *" $1 "* ]]; }

TARGET=aarch64-unknown-linux-gnu
CROSS_TIMING_SCALE=${WLNAV_CROSS_TIMING_SCALE:-5}
export CARGO_TARGET_DIR=${WLNAV_CROSS_TARGET_DIR:-target/cross}
started=$(date +%s)
step_started=$started

fail() {
  printf 'cross-check: FAILED: %b\n' "$*" >&2
  exit 1
}
step() {
  local now
  now=$(date +%s)
  echo "cross-check: $* ($((now - step_started)) s)"
  step_started=$now
}

if [ "${WLNAV_SKIP_CROSS_CHECK:-0}" = 1 ]; then
  echo "cross-check: skipped (WLNAV_SKIP_CROSS_CHECK=1)"
  exit 0
fi
if has_phase setup || has_phase run; then
  [ "$(id -u)" -eq 0 ] || fail "needs root (apt-get, binfmt_misc); run as root or set WLNAV_SKIP_CROSS_CHECK=1"
fi

# 1. Debian's cross toolchain: rustc-web (1.96, bookworm-security) puts rustc and cargo in
# /usr/bin with the arm64 standard library; the linker and C runtime of the cross gcc;
# the arm64 C library the binaries load under qemu.
if has_phase setup; then
  pkgs=(rustc-web cargo-web libstd-rust-web-dev:arm64 gcc-aarch64-linux-gnu
    libc6-dev-arm64-cross libc6:arm64 qemu-user-static binutils-aarch64-linux-gnu)
  dpkg --print-foreign-architectures | grep -qx arm64 || { dpkg --add-architecture arm64; need_update=1; }
  missing=()
  for p in "${pkgs[@]}"; do
    dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
  done
  if [ ${#missing[@]} -gt 0 ] || [ "${need_update:-0}" = 1 ]; then
    echo "cross-check: installing ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${pkgs[@]}" >/dev/null
  fi
  # wlnavd links IPOPT (trajopt): its arm64 library beside the amd64 one.
  bash scripts/arm64-ipopt.sh "$CARGO_TARGET_DIR/arm64-ipopt" || fail "arm64 IPOPT (scripts/arm64-ipopt.sh)"
fi
CARGO=/usr/bin/cargo
RUSTC=/usr/bin/rustc
export PATH=/usr/bin:$PATH RUSTC
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
# Test executables run under qemu; never with -L /usr/aarch64-linux-gnu (two C libraries
# mixed: every thread spawn hangs). The arm64 loader and libc come from libc6:arm64.
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER=qemu-aarch64-static
if has_phase setup; then
  "$RUSTC" --print target-cpus --target $TARGET | grep -qw cortex-a78ae ||
    fail "$("$RUSTC" -V) does not know target-cpu=cortex-a78ae (.cargo/config.toml)"
  step "toolchain: $("$RUSTC" -V), target-cpu cortex-a78ae known"
fi
bin=$CARGO_TARGET_DIR/$TARGET/cross

# 2. The tests start wlnavd and wlnav as child processes (arm64 executables started by an
# arm64 test under qemu): the kernel must hand them to qemu, i.e. binfmt_misc has
# qemu-aarch64 registered (the Debian package's /usr/lib/binfmt.d/qemu-aarch64.conf; flag
# F: the interpreter is opened now, so it works in any mount namespace). Containers
# without systemd-binfmt get it registered here.
binfmt=/proc/sys/fs/binfmt_misc
if has_phase run; then
  if [ ! -e $binfmt/register ]; then
    mount -t binfmt_misc binfmt_misc $binfmt 2>/dev/null ||
      fail "binfmt_misc is not mounted at $binfmt and cannot be mounted (the tests start arm64 child processes; they need qemu-aarch64 registered)"
  fi
  if [ ! -e $binfmt/qemu-aarch64 ]; then
    cat /usr/lib/binfmt.d/qemu-aarch64.conf > $binfmt/register ||
      fail "cannot register qemu-aarch64 with binfmt_misc"
  fi
  grep -q '^enabled' $binfmt/qemu-aarch64 || fail "binfmt_misc: qemu-aarch64 is registered but disabled"
fi

# 3. Build, once, in one profile (`cross`: workspace opt-level 3, dependencies 1, debug
# assertions on, no debug info;
# Cargo.toml): the test executables of the four suites run below and the binaries they,
# the examples and the package need (wlnavd, wlnav, wlnav-fleet, goal-client,
# pose-publisher, person-publisher), nothing else. Every cargo invocation here selects the same packages,
# with test targets among what it builds, so cargo resolves one feature set and compiles
# every dependency once (a `cargo test -p X` per suite, or a `cargo build` of a binary
# alone, resolves other features and rebuilt most dependencies: measured). The first, a
# `cargo test --no-run`, builds the libraries' and binaries' unit tests and the
# integration tests of the four suites (their names from `cargo metadata`; not
# wlnav-fleet's, which need mosquitto and node and run natively; not the examples'); its
# JSON messages name the executables run under qemu below. The second, a `cargo build
# --bins` with one of those tests, adds the binaries of wlnav-cli, wlnav-examples and
# wlnav-fleet, whose packages have no integration test in that selection.
suites=(control shm-ipc daemon e2e)
if has_phase build; then
  mkdir -p "$CARGO_TARGET_DIR"
  rm -f "$CARGO_TARGET_DIR/cross-build.ok"
  packages=(-p control -p shm-ipc -p daemon -p e2e -p wlnav-cli -p wlnav-examples -p wlnav-fleet)
  tests=()
  for t in $("$CARGO" metadata --locked --no-deps --format-version 1 | jq -r --arg s "${suites[*]}" '
    .packages[] | select(.name as $n | $s | split(" ") | index($n))
    | .targets[] | select(.kind == ["test"]) | .name'); do
    tests+=(--test "$t")
  done
  [ ${#tests[@]} -ge 8 ] || fail "cargo metadata names no integration tests of ${suites[*]}"
  # The build's CPU time too (its cost on free cores: (user + sys) / cores), and cargo's
  # timings report (cargo-timings/ in the target directory: which units took how long).
  TIMEFORMAT='%R s wall, %U s user + %S s sys of CPU'
  { time {
    "$CARGO" test --locked --target $TARGET --profile cross --no-run --timings "${packages[@]}" \
      --lib --bins "${tests[@]}" \
      --message-format=json-render-diagnostics >"$CARGO_TARGET_DIR/cross-build.json" &&
      "$CARGO" build --locked --target $TARGET --profile cross "${packages[@]}" --bins "${tests[@]:0:2}"
  } 2>"$CARGO_TARGET_DIR/cross-build.log"; } 2>"$CARGO_TARGET_DIR/cross-build.time" ||
    fail "cargo test --no-run / cargo build --profile cross --target $TARGET:\n$(tail -n 30 "$CARGO_TARGET_DIR/cross-build.log")"
  for b in wlnavd wlnav wlnav-fleet goal-client pose-publisher person-publisher; do
    file -L "$bin/$b" | grep -q 'ARM aarch64' || fail "$bin/$b is not an arm64 executable"
  done
  touch "$CARGO_TARGET_DIR/cross-build.ok"
  step "built the test executables and binaries for $TARGET ($(tail -n 1 "$CARGO_TARGET_DIR/cross-build.time")): $bin/{wlnavd,wlnav,wlnav-fleet,goal-client,pose-publisher,person-publisher} are arm64"
fi
if ! has_phase run; then
  echo "cross-check: ${phases// /, }: OK in $(($(date +%s) - started)) s"
  exit 0
fi
[ -f "$CARGO_TARGET_DIR/cross-build.ok" ] ||
  fail "no finished arm64 build in $CARGO_TARGET_DIR (run: bash scripts/cross-check.sh build)"

# 4. The test suites under qemu-aarch64: each test executable of the build above, run in its
# package's directory (as cargo test does). Timing limits are multiplied by
# WLNAV_TIMING_SCALE (tests/timing_scale.rs); nothing is skipped.
export WLNAV_TIMING_SCALE=$CROSS_TIMING_SCALE
export WLNAV_E2E_BIN_DIR=$bin
# package directory, target name, executable; one line each.
jq -r '
  select(.reason == "compiler-artifact" and .profile.test and .executable != null)
  | (.manifest_path | sub("/Cargo.toml$"; "")) as $dir
  | select(["control", "shm-ipc", "daemon", "tests"] | index($dir | split("/") | last))
  | "\($dir) \(.target.kind[0]):\(.target.name) \(.executable)"' \
  "$CARGO_TARGET_DIR/cross-build.json" | sort -u >"$CARGO_TARGET_DIR/cross-tests.txt"
[ "$(wc -l <"$CARGO_TARGET_DIR/cross-tests.txt")" -ge 4 ] ||
  fail "found no test executables of ${suites[*]} in $CARGO_TARGET_DIR/cross-build.json"
# One at a time by default. WLNAV_CROSS_JOBS=2 runs two side by side, the longest first
# (several executables leave a core idle: one long test, or daemons waiting for their
# tick), but measured beside other builds (load 7-8) that cost the daemon's e2e suite 6
# of 37 tests on solve time (median 144 ms against about 67 ms alone) and overruns: the
# factor leaves room for emulation, not for a second suite. Those named in
# WLNAV_CROSS_ALONE (default: daemon's soak, whose resident-memory check under qemu-user
# counts the emulator and grew on a loaded machine) run afterwards, alone.
jobs=${WLNAV_CROSS_JOBS:-1}
alone=" ${WLNAV_CROSS_ALONE-daemon:test:soak} "
# package directory, target name, executable -> its log; "status wall user sys" in $log.status
run_suite() {
  local dir=$1 name=$2 exe=$3 cwd=$1 status=0 t0
  local log=$CARGO_TARGET_DIR/cross-test-$(basename "$dir")-${name//[:\/]/-}.log
  # The end-to-end suite's wlnavd finds the default weights (critic-weights/avant635)
  # through its working directory: the arm64 binaries are not under target/<profile>/,
  # from where it would find the repository. Every other suite runs in its package's
  # directory, as cargo test does.
  if [ "$(basename "$dir")" = tests ]; then cwd=$PWD; fi
  t0=$(date +%s)
  # Directly (binfmt_misc hands it to qemu-aarch64-static, as it does the wlnavd and wlnav
  # the tests start); stdin closed; the harness's own parallelism (one thread per core).
  # Its CPU time (user, sys; with the processes it started) beside its wall time.
  TIMEFORMAT='%U %S'
  { time { (cd "$cwd" && "$exe" </dev/null) >"$log" 2>&1; }; } 2>"$log.cpu" || status=$?
  echo "$status $(($(date +%s) - t0)) $(tail -n 1 "$log.cpu")" >"$log.status"
}
export -f run_suite
export CARGO_TARGET_DIR
# Longest first (measured under qemu: daemon_ipc, soak, daemon's e2e, mpc_alloc, cli).
order() {
  local first=" tests:test:daemon_ipc daemon:test:e2e control:test:mpc_alloc tests:test:cli tests:test:inputs tests:test:stop_squat "
  while read -r dir name exe; do
    key="$(basename "$dir"):$name"
    if [[ $alone == *" $key "* ]]; then continue; fi
    if [[ $first == *" $key "* ]]; then echo "0 $dir $name $exe"; else echo "1 $dir $name $exe"; fi
  done <"$CARGO_TARGET_DIR/cross-tests.txt" | sort -s -k1,1n | cut -d' ' -f2-
}
rm -f "$CARGO_TARGET_DIR"/cross-test-*.status
order | xargs -P "$jobs" -L 1 bash -c 'run_suite "$@"' _
while read -r dir name exe; do
  if [[ $alone == *" $(basename "$dir"):$name "* ]]; then run_suite "$dir" "$name" "$exe"; fi
done <"$CARGO_TARGET_DIR/cross-tests.txt"
total_tests=0
failed=()
cpu_total=0
# Children the test kit restarted (a wlnavd child silent for half its start-up limit under
# emulation: test-kit/src/daemon.rs prints one `wlnav-test-kit: RESTARTED` line each, past
# the harness's capture), counted per suite and in all.
restarted_total=0
while read -r dir name exe; do
  log=$CARGO_TARGET_DIR/cross-test-$(basename "$dir")-${name//[:\/]/-}.log
  [ -f "$log.status" ] || { failed+=("$(basename "$dir") $name (did not run)"); continue; }
  read -r status wall user sys <"$log.status"
  cpu_total=$(awk -v t="$cpu_total" -v u="$user" -v s="$sys" 'BEGIN { print t + u + s }')
  restarted=$(grep -c '^wlnav-test-kit: RESTARTED' "$log" || true)
  restarted_total=$((restarted_total + restarted))
  if [ "$restarted" -gt 0 ]; then
    echo "cross-check:   $(basename "$dir") $name: $restarted silent child(ren) restarted:" >&2
    grep '^wlnav-test-kit: RESTARTED' "$log" >&2
  fi
  if [ "$status" != 0 ]; then
    echo "cross-check:   $(basename "$dir") $name FAILED (exit $status, $wall s; log: $log):" >&2
    grep -E '^test .*FAILED|^failures:|panicked|^test result' "$log" >&2 || tail -n 40 "$log" >&2
    failed+=("$(basename "$dir") $name")
    continue
  fi
  result=$(grep -E '^test result' "$log" | tail -n 1)
  n=$(echo "$result" | sed -E 's/.* ([0-9]+) passed.*/\1/')
  total_tests=$((total_tests + n))
  echo "cross-check:   $(basename "$dir") $name: $result ($wall s wall, $user s user + $sys s sys of CPU)"
done <"$CARGO_TARGET_DIR/cross-tests.txt"
[ ${#failed[@]} -eq 0 ] ||
  fail "under qemu-aarch64 (WLNAV_TIMING_SCALE=$WLNAV_TIMING_SCALE): ${failed[*]}"
unset WLNAV_E2E_BIN_DIR
step "$total_tests tests of ${suites[*]} pass under qemu-aarch64 (WLNAV_TIMING_SCALE=$WLNAV_TIMING_SCALE; $jobs at a time; $cpu_total s of CPU; $restarted_total silent children restarted)"

# 5. The examples (the Rust ones arm64 too; the Python one native, over the same shared
# memory) against an arm64 wlnavd --sim.
WLNAV_EXAMPLES_BIN_DIR=$bin bash scripts/examples.sh ||
  fail "examples against the arm64 wlnavd"
step "examples pass against the arm64 wlnavd --sim"

# 6. The arm64 package, from the binaries just built (as scripts/package-check.sh does for
# amd64), checked against the amd64 one.
CARGO_DEB_VERSION=3.8.0
if [ "$(cargo deb --version 2>/dev/null)" != "cargo-deb $CARGO_DEB_VERSION" ]; then
  cargo install cargo-deb --version "$CARGO_DEB_VERSION" --locked --quiet
fi
stage=$CARGO_TARGET_DIR/package
rm -rf "$stage"
mkdir -p "$stage/$TARGET/release" "$stage/release"
cp "$bin/wlnavd" "$bin/wlnav" "$bin/wlnav-fleet" "$stage/$TARGET/release/"
CARGO_TARGET_DIR=$stage cargo deb -p daemon --target $TARGET --no-build --locked --strip --fast \
  --output "$stage/" --quiet >/dev/null || fail "cargo deb --target $TARGET"
deb_arm=$(ls "$stage"/wlnavd_*_arm64.deb 2>/dev/null | head -1)
[ -f "$deb_arm" ] || fail "cargo deb made no wlnavd_*_arm64.deb in $stage"
deb_amd=$(ls target/package-check/wlnavd_*_amd64.deb 2>/dev/null | head -1 || true)
if [ -z "$deb_amd" ]; then
  # No package check ran before (e.g. WLNAV_SKIP_PACKAGE_CHECK=1): package target/debug.
  for b in wlnavd wlnav wlnav-fleet; do cp "target/debug/$b" "$stage/release/" || fail "target/debug/$b missing"; done
  CARGO_TARGET_DIR=$stage cargo deb -p daemon --no-build --locked --fast --output "$stage/" \
    --quiet >/dev/null || fail "cargo deb (amd64)"
  deb_amd=$(ls "$stage"/wlnavd_*_amd64.deb | head -1)
fi
[ "$(dpkg-deb -f "$deb_arm" Architecture)" = arm64 ] || fail "$deb_arm: Architecture is not arm64"
[ "$(dpkg-deb -f "$deb_amd" Architecture)" = amd64 ] || fail "$deb_amd: Architecture is not amd64"
contents() { dpkg-deb -c "$1" | awk '{print $1, $2, $6}' | sort -k3; }
diff <(contents "$deb_amd") <(contents "$deb_arm") >/dev/null ||
  fail "the arm64 and amd64 packages differ in paths, modes or owners:\n$(diff <(contents "$deb_amd") <(contents "$deb_arm"))"
for f in Depends Conffiles Version Package; do
  a=$(dpkg-deb -f "$deb_amd" $f | sed 's/libc6 (>= [^)]*)/libc6/')
  r=$(dpkg-deb -f "$deb_arm" $f | sed 's/libc6 (>= [^)]*)/libc6/')
  [ "$a" = "$r" ] || fail "field $f differs: amd64 '$a', arm64 '$r'"
done
ex=$stage/extract
dpkg-deb -x "$deb_arm" "$ex"
for b in wlnavd wlnav wlnav-fleet; do
  file "$ex/usr/bin/$b" | grep -q 'ARM aarch64' || fail "$deb_arm: usr/bin/$b is not arm64: $(file "$ex/usr/bin/$b")"
done
# The packaged daemon on the packaged configuration and weights (paths moved into the
# extracted tree), under qemu.
sed "s#/usr/share/wlnav/#$(realpath "$ex")/usr/share/wlnav/#" "$ex/etc/wlnav/wlnavd.toml" > "$stage/wlnavd.toml"
qemu-aarch64-static "$ex/usr/bin/wlnavd" --config "$stage/wlnavd.toml" --check-config >"$stage/check-config.log" 2>&1 ||
  fail "packaged arm64 wlnavd --check-config:\n$(tail -n 20 "$stage/check-config.log")"
qemu-aarch64-static "$ex/usr/bin/wlnav" --help >/dev/null || fail "packaged arm64 wlnav --help"
qemu-aarch64-static "$ex/usr/bin/wlnav-fleet" --config "$ex/etc/wlnav/wlnav-fleet.toml" --check-config \
  >"$stage/fleet-check-config.log" 2>&1 ||
  fail "packaged arm64 wlnav-fleet --check-config:\n$(tail -n 20 "$stage/fleet-check-config.log")"
step "built $deb_arm: arm64, same files, modes and fields as $(basename "$deb_amd"); its wlnavd and wlnav-fleet --check-config pass under qemu"

echo "cross-check: OK in $(($(date +%s) - started)) s"
