#!/usr/bin/env bash
# Package check (issue 18), run by scripts/test.sh after the tests: builds the amd64
# Debian package with cargo-deb, installs it, checks what it installed (files, conffile,
# user and group, unit not enabled, `systemd-analyze verify`, `wlnavd --check-config`
# of the installed configuration and weights as user wlnav), removes it and checks that
# nothing but the conffile is left; then purges it.
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
for b in wlnavd wlnav; do
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
trap 'rm -f "$before" "$after"; dpkg-query -W "$PKG" >/dev/null 2>&1 && dpkg -P "$PKG" >/dev/null 2>&1 || true' EXIT
snapshot > "$before"

dpkg -i "$deb" || fail "dpkg -i $deb"

for f in /usr/bin/wlnavd /usr/bin/wlnav /lib/systemd/system/wlnavd.service \
  /etc/wlnav/wlnavd.toml /usr/lib/sysusers.d/wlnavd.conf \
  /usr/share/wlnav/critic-weights/avant635/critic.safetensors \
  /usr/share/wlnav/critic-weights/avant635/actor.safetensors \
  /usr/share/wlnav/critic-weights/large-loader/critic.safetensors \
  /usr/share/wlnav/critic-weights/large-loader/actor.safetensors \
  /usr/share/doc/wlnavd/examples/wlnavd.service.d/realtime.conf; do
  [ -e "$f" ] || fail "not installed: $f"
done
dpkg-query -W -f='${Conffiles}\n' "$PKG" | grep -q '^ /etc/wlnav/wlnavd.toml ' ||
  fail "/etc/wlnav/wlnavd.toml is not a conffile"
getent passwd wlnav >/dev/null || fail "user wlnav not created (sysusers.d)"
getent group wlnav >/dev/null || fail "group wlnav not created (sysusers.d)"
if ls /etc/systemd/system/*.wants/wlnavd.service >/dev/null 2>&1; then
  fail "the package enabled wlnavd.service (it must not: CAN may not exist yet)"
fi

verify=$(systemd-analyze verify /lib/systemd/system/wlnavd.service 2>&1) ||
  fail "systemd-analyze verify /lib/systemd/system/wlnavd.service:\n$verify"
if echo "$verify" | grep -q 'wlnavd.service'; then
  fail "systemd-analyze verify warns about the unit:\n$verify"
fi

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

dpkg -r "$PKG" || fail "dpkg -r $PKG"
snapshot > "$after"
# After removal only the conffile (and its directory) may remain.
added=$(comm -13 "$before" "$after" | grep -v -x -e /etc/wlnav -e /etc/wlnav/wlnavd.toml || true)
removed=$(comm -23 "$before" "$after" || true)
[ -z "$added" ] || fail "left behind after dpkg -r:\n$added"
[ -z "$removed" ] || fail "missing after install and removal (files the package must not touch):\n$removed"
[ -f /etc/wlnav/wlnavd.toml ] || fail "dpkg -r removed the conffile"

dpkg -P "$PKG" >/dev/null || fail "dpkg -P $PKG"
[ ! -e /etc/wlnav/wlnavd.toml ] || fail "dpkg -P left /etc/wlnav/wlnavd.toml"
echo "package-check: OK in $(($(date +%s) - started)) s (install, verify, check-config, remove: only the conffile left, purge)"
