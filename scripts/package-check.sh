#!/usr/bin/env bash
# Package check (issue 18), run by scripts/test.sh after the tests: builds the amd64
# Debian package with cargo-deb, installs it, checks what it installed (files, conffiles,
# user and group, units not enabled, `systemd-analyze verify` of both units (wlnavd and
# the fleet link wlnav-fleet), `wlnav-fleet --check-config` of its installed configuration,
# `wlnavd --check-config`
# of the installed configuration and weights as user wlnav; the same under
# `qemu-x86_64-static -cpu Haswell`, the oldest CPU the x86-64-v3 baseline claims; the
# installed daemon, run as user wlnav, reached by a client of another user in group wlnav
# and refusing one outside it), removes it and checks that nothing but the conffile is
# left; then purges it.
#
# It packages the binaries the test build just made (target/debug/, profile `dev`), so
# CI compiles nothing more than cargo-deb itself: this checks the package, it is not the
# package to ship (README, "Field installation": `cargo build --release ... && cargo deb
# -p daemon --no-build`). WLNAV_PACKAGE_BIN_DIR=target/release checks release binaries.
#
# Needs root (dpkg -i). It installs a system package on the machine it runs on: it
# refuses when wlnavd is already installed, and WLNAV_SKIP_PACKAGE_CHECK=1 skips it
# (workstations). Any failure is fatal and says what failed.
set -euo pipefail
cd "$(dirname "$0")/.."

CARGO_DEB_VERSION=3.8.0
PKG=wlnavd
started=$(date +%s)

fail() {
  printf 'package-check: FAILED: %b\n' "$*" >&2
  exit 1
}

if [ "${WLNAV_SKIP_PACKAGE_CHECK:-0}" = 1 ]; then
  echo "package-check: skipped (WLNAV_SKIP_PACKAGE_CHECK=1)"
  exit 0
fi
[ "$(id -u)" -eq 0 ] || fail "needs root (dpkg -i); run as root or set WLNAV_SKIP_PACKAGE_CHECK=1"
if dpkg-query -W -f='${Status}' "$PKG" 2>/dev/null | grep -q 'installed'; then
  fail "$PKG is already installed on this machine; this check would replace it: remove it (dpkg -P $PKG) or set WLNAV_SKIP_PACKAGE_CHECK=1"
fi

# cargo-deb, pinned.
if [ "$(cargo deb --version 2>/dev/null)" != "cargo-deb $CARGO_DEB_VERSION" ]; then
  echo "package-check: installing cargo-deb $CARGO_DEB_VERSION"
  cargo install cargo-deb --version "$CARGO_DEB_VERSION" --locked --quiet
fi

# Stage the binaries as cargo-deb's `target/release/` and package without building.
bin_dir=${WLNAV_PACKAGE_BIN_DIR:-target/debug}
stage=target/package-check
rm -rf "$stage"
mkdir -p "$stage/release"
for b in wlnavd wlnav wlnav-fleet; do
  [ -x "$bin_dir/$b" ] || fail "$bin_dir/$b missing (cargo test --workspace builds it)"
  cp "$bin_dir/$b" "$stage/release/"
done
CARGO_TARGET_DIR=$stage cargo deb -p daemon --no-build --locked --strip --fast \
  --output "$stage/" --quiet >/dev/null
deb=$(ls "$stage"/${PKG}_*_amd64.deb 2>/dev/null | head -1)
[ -f "$deb" ] || fail "cargo deb made no package in $stage"
echo "package-check: built $deb"

# Files before, for the leftover check (package databases and caches excluded).
snapshot() {
  find /etc /usr /var -xdev \( -path /var/lib/dpkg -o -path /var/cache -o -path /var/lib/apt \
    -o -path /var/log/apt -o -path /var/tmp -o -path /var/log/journal \) -prune -o -print \
    | grep -v -e '^/var/log/dpkg.log' -e '^/var/log/alternatives.log' | sort
}
before=$(mktemp)
after=$(mktemp)
# Two client users for the group check (created before the snapshot, removed at the end):
# one joins group wlnav once the package created it, the other never does.
MEMBER=wlnav-check-member
OUTSIDER=wlnav-check-outsider
for u in $MEMBER $OUTSIDER; do
  id -u "$u" >/dev/null 2>&1 || useradd --system --no-create-home --shell /usr/sbin/nologin "$u" ||
    fail "useradd $u"
done
daemon_pid=
cleanup() {
  [ -n "$daemon_pid" ] && kill "$daemon_pid" 2>/dev/null || true
  rm -f "$before" "$after"
  dpkg-query -W "$PKG" >/dev/null 2>&1 && dpkg -P "$PKG" >/dev/null 2>&1 || true
  for u in $MEMBER $OUTSIDER; do userdel "$u" >/dev/null 2>&1 || true; done
}
trap cleanup EXIT
snapshot > "$before"

dpkg -i "$deb" || fail "dpkg -i $deb"

for f in /usr/bin/wlnavd /usr/bin/wlnav /usr/bin/wlnav-fleet /lib/systemd/system/wlnavd.service \
  /lib/systemd/system/wlnav-fleet.service /etc/wlnav/wlnav-fleet.toml \
  /usr/share/doc/wlnavd/wlnav-fleet.md \
  /etc/wlnav/wlnavd.toml /usr/lib/sysusers.d/wlnavd.conf /usr/lib/tmpfiles.d/wlnavd.conf \
  /usr/share/wlnav/critic-weights/avant635/critic.safetensors \
  /usr/share/wlnav/critic-weights/avant635/actor.safetensors \
  /usr/share/wlnav/critic-weights/large-loader/critic.safetensors \
  /usr/share/wlnav/critic-weights/large-loader/actor.safetensors \
  /usr/share/doc/wlnavd/examples/wlnavd.service.d/realtime.conf; do
  [ -e "$f" ] || fail "not installed: $f"
done
for c in /etc/wlnav/wlnavd.toml /etc/wlnav/wlnav-fleet.toml; do
  dpkg-query -W -f='${Conffiles}\n' "$PKG" | grep -q "^ $c " || fail "$c is not a conffile"
done
getent passwd wlnav >/dev/null || fail "user wlnav not created (sysusers.d)"
getent group wlnav >/dev/null || fail "group wlnav not created (sysusers.d)"
if ls /etc/systemd/system/*.wants/wlnavd.service >/dev/null 2>&1; then
  fail "the package enabled wlnavd.service (it must not: CAN may not exist yet)"
fi
if ls /etc/systemd/system/*.wants/wlnav-fleet.service >/dev/null 2>&1; then
  fail "the package enabled wlnav-fleet.service (it must not: the broker and serial number are the site's)"
fi

# Both units (systemd-analyze comes with systemd, which the package depends on). It checks
# that the binaries of ExecStart=/ExecStartPre= exist and that every setting is known;
# any line naming the unit is a warning about it, and fails the check.
command -v systemd-analyze >/dev/null || fail "systemd-analyze missing (package systemd, a dependency of $PKG)"
for unit in wlnavd.service wlnav-fleet.service; do
  verify=$(systemd-analyze verify /lib/systemd/system/$unit 2>&1) ||
    fail "systemd-analyze verify /lib/systemd/system/$unit:\n$verify"
  if echo "$verify" | grep -q "$unit"; then
    fail "systemd-analyze verify warns about $unit:\n$verify"
  fi
done
# The fleet link's unit: started after the daemon, as user wlnav, with the conffile.
fleet_unit=/lib/systemd/system/wlnav-fleet.service
grep -qx 'After=wlnavd.service.*' $fleet_unit || fail "$fleet_unit: no After=wlnavd.service"
grep -qx 'User=wlnav' $fleet_unit || fail "$fleet_unit: does not run as user wlnav"
grep -q '^ExecStart=/usr/bin/wlnav-fleet .*--config /etc/wlnav/wlnav-fleet.toml' $fleet_unit ||
  fail "$fleet_unit: ExecStart= does not pass --config /etc/wlnav/wlnav-fleet.toml"
/usr/bin/wlnav-fleet --help | grep -q -- '--serial-number' || fail "/usr/bin/wlnav-fleet --help"
# As the unit's ExecStartPre does: the service user reads and checks the configuration.
out=$(runuser -u wlnav -- /usr/bin/wlnav-fleet --config /etc/wlnav/wlnav-fleet.toml --check-config 2>&1) ||
  fail "wlnav-fleet --check-config of /etc/wlnav/wlnav-fleet.toml (as user wlnav):\n$out"
# ... and refuses a broken one, saying where.
bad=$(mktemp --suffix=.toml)
printf 'state_interval = "often"\n' > "$bad"
chmod 644 "$bad"
set +e
out=$(runuser -u wlnav -- /usr/bin/wlnav-fleet --config "$bad" --check-config 2>&1)
code=$?
set -e
rm -f "$bad"
[ $code -ne 0 ] || fail "wlnav-fleet --check-config accepted a configuration with state_interval = \"often\""
echo "$out" | grep -q 'state_interval' || fail "wlnav-fleet --check-config refused a bad configuration without naming the key:\n$out"
echo "package-check: wlnav-fleet installed: unit verified (After=wlnavd.service, user wlnav), --help runs, --check-config passes on /etc/wlnav/wlnav-fleet.toml as user wlnav and refuses a bad file"

/usr/bin/wlnavd --config /etc/wlnav/wlnavd.toml --print-config |
  grep -q '^critic = "/usr/share/wlnav/critic-weights/avant635/critic.safetensors"' ||
  fail "the installed configuration does not point at /usr/share/wlnav/critic-weights/avant635/"
# As the unit's ExecStartPre does: the service user reads the configuration and weights.
runuser -u wlnav -- /usr/bin/wlnavd --config /etc/wlnav/wlnavd.toml --check-config ||
  fail "wlnavd --check-config of the installed configuration and weights (as user wlnav)"
# Another machine installed as the configuration's comment says: its weights, no [machine].
other=$(mktemp --suffix=.toml)
sed -e '/^\[machine\]/,/^$/d' -e 's#critic-weights/avant635/#critic-weights/large-loader/#' \
  /etc/wlnav/wlnavd.toml > "$other"
chmod 644 "$other"
runuser -u wlnav -- /usr/bin/wlnavd --config "$other" --print-config | grep -q '^l_f = 0.9$' ||
  fail "with the large loader's weights and no [machine], wlnavd does not take L_f 0.9 from them"
runuser -u wlnav -- /usr/bin/wlnavd --config "$other" --check-config ||
  fail "wlnavd --check-config with the large loader's installed weights (as user wlnav)"
rm -f "$other"
/usr/bin/wlnav --help >/dev/null || fail "/usr/bin/wlnav --help"

# The shipped baseline (x86-64-v3, .cargo/config.toml): the packaged daemon runs on a
# Haswell, the oldest CPU the baseline claims (qemu's TCG has AVX2, FMA, BMI2; a binary built
# for the CI machine's AVX-512 dies here with SIGILL).
qemu-x86_64-static -cpu Haswell /usr/bin/wlnavd --config /etc/wlnav/wlnavd.toml --check-config \
  >/dev/null 2>"$stage/haswell.log" ||
  fail "the packaged wlnavd --check-config under qemu-x86_64-static -cpu Haswell:\n$(grep -v "TCG doesn't support" "$stage/haswell.log" | tail -n 20)"
qemu-x86_64-static -cpu Haswell /usr/bin/wlnav-fleet --config /etc/wlnav/wlnav-fleet.toml --check-config \
  >/dev/null 2>"$stage/haswell-fleet.log" ||
  fail "the packaged wlnav-fleet --check-config under qemu-x86_64-static -cpu Haswell:\n$(grep -v "TCG doesn't support" "$stage/haswell-fleet.log" | tail -n 20)"
echo "package-check: the packaged wlnavd and wlnav-fleet --check-config pass under qemu-x86_64-static -cpu Haswell"

# Group access (issue 28): the daemon as user wlnav (as the unit runs it; here on the
# simulated machine, faster than real time), a client of another user in group wlnav sends
# a goal, waits for its outcome and reads telemetry; a user outside the group is refused.
iox=$(stat -c '%a %U %G' /tmp/iceoryx2 2>/dev/null || true)
[ "$iox" = "2770 root wlnav" ] || fail "/tmp/iceoryx2 is '$iox', not '2770 root wlnav' (tmpfiles.d/wlnavd.conf)"
usermod -aG wlnav $MEMBER || fail "usermod -aG wlnav $MEMBER"
prefix=wlnav-package-check-$$
daemon_log=$stage/group-daemon.log
# The installed configuration without the CAN log (/var/log/wlnav is the unit's
# LogsDirectory, which exists only when systemd starts the unit).
group_config=$(mktemp --suffix=.toml)
sed '/\/var\/log\/wlnav/d' /etc/wlnav/wlnavd.toml > "$group_config"
chmod 644 "$group_config"
runuser -u wlnav -- /usr/bin/wlnavd --config "$group_config" --sim --prefix "$prefix" \
  --time-scale 4 >"$daemon_log" 2>&1 &
daemon_pid=$!
as_member() { runuser -u $MEMBER -- /usr/bin/wlnav --prefix "$prefix" "$@"; }
ok=
for _ in $(seq 1 100); do
  if as_member watch --count 1 --silence-timeout 1 >/dev/null 2>&1; then ok=1; break; fi
  kill -0 "$daemon_pid" 2>/dev/null || fail "wlnavd (user wlnav) exited:\n$(tail -n 20 "$daemon_log")"
  sleep 0.2
done
[ -n "$ok" ] || fail "no telemetry for $MEMBER (group wlnav) from wlnavd (user wlnav) within 20 s:\n$(as_member watch --count 1 2>&1 | tail -n 5)\ndaemon log:\n$(tail -n 20 "$daemon_log")"
out=$(as_member goal 2 0 0 --wait --timeout 60 2>&1) ||
  fail "$MEMBER (group wlnav) could not drive a goal to success (exit $?):\n$out\ndaemon log:\n$(tail -n 20 "$daemon_log")"
echo "$out" | grep -q '^succeeded' || fail "goal of $MEMBER did not succeed:\n$out"
as_member watch --count 3 >/dev/null || fail "$MEMBER cannot read telemetry"
set +e
refused=$(runuser -u $OUTSIDER -- /usr/bin/wlnav --prefix "$prefix" goal 2 0 0 2>&1)
code=$?
set -e
[ $code -ne 0 ] || fail "$OUTSIDER (not in group wlnav) sent a goal:\n$refused"
echo "$refused" | grep -qi 'permission\|group wlnav' ||
  fail "$OUTSIDER was refused (exit $code) but the message does not say why:\n$refused"
kill -TERM "$daemon_pid"
wait "$daemon_pid" || true   # runuser passes SIGTERM on and reports "killed"
daemon_pid=
grep -q 'stopped (Shutdown)' "$daemon_log" ||
  fail "wlnavd (user wlnav) did not stop cleanly on SIGTERM:\n$(tail -n 20 "$daemon_log")"
rm -f "$group_config"
echo "package-check: $MEMBER (group wlnav) reached a goal and read telemetry of wlnavd running as wlnav; $OUTSIDER was refused (exit $code): $(echo "$refused" | head -n 1)"

dpkg -r "$PKG" || fail "dpkg -r $PKG"
snapshot > "$after"
# After removal only the conffile (and its directory) may remain.
added=$(comm -13 "$before" "$after" | grep -v -x -e /etc/wlnav -e /etc/wlnav/wlnavd.toml \
  -e /etc/wlnav/wlnav-fleet.toml || true)
removed=$(comm -23 "$before" "$after" || true)
[ -z "$added" ] || fail "left behind after dpkg -r:\n$added"
[ -z "$removed" ] || fail "missing after install and removal (files the package must not touch):\n$removed"
for c in /etc/wlnav/wlnavd.toml /etc/wlnav/wlnav-fleet.toml; do
  [ -f $c ] || fail "dpkg -r removed the conffile $c"
done

dpkg -P "$PKG" >/dev/null || fail "dpkg -P $PKG"
for c in /etc/wlnav/wlnavd.toml /etc/wlnav/wlnav-fleet.toml; do
  [ ! -e $c ] || fail "dpkg -P left $c"
done
echo "package-check: OK in $(($(date +%s) - started)) s (install, verify, check-config, fleet link, Haswell, group access, remove: only the conffiles left, purge)"
