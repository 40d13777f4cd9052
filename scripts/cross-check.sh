#!/usr/bin/env bash
# Cross check for the Jetson AGX Orin (issue 28), run by scripts/test.sh after the package
# check: builds the deployable crates and the test suites for aarch64-unknown-linux-gnu
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
# Everything arm64 is built once, in the profile `cross` (Cargo.toml: optimised, debug
# assertions on, no debug info), test executables and binaries in one cargo invocation;
# the test executables then run directly under qemu. The package is checked, not shipped
# (README, "The Jetson"). The build goes to target/cross (Debian's rustc 1.96 is not the
# workspace's toolchain, so nothing would be shared with target/, and builds of both never
# wait for each other's lock; WLNAV_CROSS_TARGET_DIR moves it). Needs root (apt-get,
# binfmt_misc). WLNAV_SKIP_CROSS_CHECK=1 skips it. Each step prints its time in seconds.
set -euo pipefail
cd "$(dirname "$0")/.."

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
[ "$(id -u)" -eq 0 ] || fail "needs root (apt-get, binfmt_misc); run as root or set WLNAV_SKIP_CROSS_CHECK=1"

# 1. Debian's cross toolchain: rustc-web (1.96, bookworm-security) puts rustc and cargo in
# /usr/bin with the arm64 standard library; the linker and C runtime of the cross gcc;
# the arm64 C library the binaries load under qemu.
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
CARGO=/usr/bin/cargo
RUSTC=/usr/bin/rustc
export PATH=/usr/bin:$PATH RUSTC
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
# Test executables run under qemu; never with -L /usr/aarch64-linux-gnu (two C libraries
# mixed: every thread spawn hangs). The arm64 loader and libc come from libc6:arm64.
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER=qemu-aarch64-static
"$RUSTC" --print target-cpus --target $TARGET | grep -qw cortex-a78ae ||
  fail "$("$RUSTC" -V) does not know target-cpu=cortex-a78ae (.cargo/config.toml)"
step "toolchain: $("$RUSTC" -V), target-cpu cortex-a78ae known"

# 2. The tests start wlnavd and wlnav as child processes (arm64 executables started by an
# arm64 test under qemu): the kernel must hand them to qemu, i.e. binfmt_misc has
# qemu-aarch64 registered (the Debian package's /usr/lib/binfmt.d/qemu-aarch64.conf; flag
# F: the interpreter is opened now, so it works in any mount namespace). Containers
# without systemd-binfmt get it registered here.
binfmt=/proc/sys/fs/binfmt_misc
if [ ! -e $binfmt/register ]; then
  mount -t binfmt_misc binfmt_misc $binfmt 2>/dev/null ||
    fail "binfmt_misc is not mounted at $binfmt and cannot be mounted (the tests start arm64 child processes; they need qemu-aarch64 registered)"
fi
if [ ! -e $binfmt/qemu-aarch64 ]; then
  cat /usr/lib/binfmt.d/qemu-aarch64.conf > $binfmt/register ||
    fail "cannot register qemu-aarch64 with binfmt_misc"
fi
grep -q '^enabled' $binfmt/qemu-aarch64 || fail "binfmt_misc: qemu-aarch64 is registered but disabled"

# 3. Build, once, in one profile (`cross`: optimised, debug assertions on, no debug info;
# Cargo.toml): the test executables of the four suites run below and the binaries they and
# the examples start (wlnavd, wlnav, goal-client, pose-publisher). One `cargo test
# --no-run` over one package selection, so every dependency is compiled once with one
# feature set; the executables are taken from its JSON messages and run directly under
# qemu below (a `cargo test -p X` per suite, or a separate `cargo build` of one binary,
# resolves features differently and rebuilds most dependencies: measured, a separate
# `cargo build -p wlnav-fleet` started over from proc-macro2 and syn). wlnav-fleet is in
# the selection for its binary (the package carries it); its tests need mosquitto and node
# and are built, not run, here.
mkdir -p "$CARGO_TARGET_DIR"
suites=(control shm-ipc daemon e2e)
# The build's CPU time too (its cost on free cores: (user + sys) / cores), and cargo's
# timings report (cargo-timings/ in the target directory: which units took how long).
TIMEFORMAT='%R s wall, %U s user + %S s sys of CPU'
{ time "$CARGO" test --locked --target $TARGET --profile cross --no-run --timings \
  -p control -p shm-ipc -p daemon -p e2e -p wlnav-cli -p wlnav-examples -p wlnav-fleet \
  --message-format=json-render-diagnostics >"$CARGO_TARGET_DIR/cross-build.json" 2>"$CARGO_TARGET_DIR/cross-build.log"; } \
  2>"$CARGO_TARGET_DIR/cross-build.time" ||
  fail "cargo test --no-run --profile cross --target $TARGET:\n$(tail -n 30 "$CARGO_TARGET_DIR/cross-build.log")"
bin=$CARGO_TARGET_DIR/$TARGET/cross
for b in wlnavd wlnav wlnav-fleet goal-client pose-publisher; do
  file -L "$bin/$b" | grep -q 'ARM aarch64' || fail "$bin/$b is not an arm64 executable"
done
step "built the test executables and binaries for $TARGET ($(tail -n 1 "$CARGO_TARGET_DIR/cross-build.time")): $bin/{wlnavd,wlnav,wlnav-fleet,goal-client,pose-publisher} are arm64"

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
total_tests=0
while read -r dir name exe; do
  log=$CARGO_TARGET_DIR/cross-test-$(basename "$dir")-${name//[:\/]/-}.log
  t0=$(date +%s)
  # The end-to-end suite's wlnavd finds the default weights (critic-weights/avant635)
  # through its working directory: the arm64 binaries are not under target/<profile>/,
  # from where it would find the repository. Every other suite runs in its package's
  # directory, as cargo test does.
  cwd=$dir
  [ "$(basename "$dir")" = tests ] && cwd=$PWD
  # Directly (binfmt_misc hands it to qemu-aarch64-static, as it does the wlnavd and wlnav
  # the tests start); stdin closed; the harness's own parallelism (one thread per core).
  if ! (cd "$cwd" && "$exe" </dev/null) >"$log" 2>&1; then
    grep -E '^test .*FAILED|^failures:|panicked|^test result' "$log" >&2 || tail -n 40 "$log" >&2
    fail "$(basename "$dir") $name under qemu-aarch64 (WLNAV_TIMING_SCALE=$WLNAV_TIMING_SCALE; log: $log)"
  fi
  result=$(grep -E '^test result' "$log" | tail -n 1)
  n=$(echo "$result" | sed -E 's/.* ([0-9]+) passed.*/\1/')
  total_tests=$((total_tests + n))
  echo "cross-check:   $(basename "$dir") $name: $result ($(($(date +%s) - t0)) s)"
done <"$CARGO_TARGET_DIR/cross-tests.txt"
unset WLNAV_E2E_BIN_DIR
step "$total_tests tests of ${suites[*]} pass under qemu-aarch64 (WLNAV_TIMING_SCALE=$WLNAV_TIMING_SCALE)"

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
deb_amd=$(ls target/package-check/wlnavd_*_amd64.deb 2>/dev/null | head -1)
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
