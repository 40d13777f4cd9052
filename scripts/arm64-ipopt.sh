#!/usr/bin/env bash
# Debian's arm64 IPOPT beside the amd64 one, for the arm64 build and its runs under qemu
# (scripts/cross-check.sh setup; root, the arm64 foreign architecture enabled). wlnavd links
# IPOPT (trajopt, issue 42); on the Jetson it is Debian's coinor-libipopt1v5, installed as
# the package's dependency. Here the amd64 coinor-libipopt1v5 owns /usr/lib/libipopt.so.1
# and is not Multi-Arch: same, so apt cannot install its arm64 build beside it: that build
# is repacked as coinor-libipopt1v5-arm64-local:arm64 with the library in
# /usr/lib/aarch64-linux-gnu/ (owned by dpkg: its DEBIAN/shlibs still names
# coinor-libipopt1v5, so cargo-deb's `$auto` gives the arm64 package the amd64 one's
# Depends; an unowned copy gives it no Depends at all, silently). Its own dependencies are
# Multi-Arch: same and come from apt. The same version as the amd64 library; a rerun with
# it installed does nothing.
set -euo pipefail
work=$1
LOCAL=coinor-libipopt1v5-arm64-local
export DEBIAN_FRONTEND=noninteractive
ver=$(dpkg-query -W -f='${Version}' coinor-libipopt1v5 2>/dev/null) ||
  { echo "arm64-ipopt: the amd64 coinor-libipopt1v5 is not installed (scripts/apt-packages.txt)" >&2; exit 1; }
if [ "$(dpkg-query -W -f='${Version}' "$LOCAL:arm64" 2>/dev/null || true)" = "$ver" ]; then
  exit 0
fi
apt-get install -y -qq --no-install-recommends libmumps-seq-5.5:arm64 liblapack3:arm64 \
  libblas3:arm64 libgfortran5:arm64 libstdc++6:arm64 libgcc-s1:arm64 >/dev/null
rm -rf "$work"
mkdir -p "$work"
cd "$work"
chown _apt "$work" 2>/dev/null || true # apt-get download as root: no sandbox warning
apt-get download -qq "coinor-libipopt1v5:arm64=$ver"
dpkg-deb -R coinor-libipopt1v5_*_arm64.deb root
mkdir -p root/usr/lib/aarch64-linux-gnu
mv root/usr/lib/libipopt.so.1* root/usr/lib/aarch64-linux-gnu/
rm -rf root/usr/share # its /usr/share/doc would clash with the amd64 package's
sed -i -e "s/^Package: .*/Package: $LOCAL/" -e '/^Conflicts:/d' -e '/^Replaces:/d' \
  -e '/^Source:/d' -e '/^Architecture:/a Multi-Arch: same' root/DEBIAN/control
(cd root && find usr -type f -exec md5sum {} + >DEBIAN/md5sums)
grep -qx 'libipopt 1 coinor-libipopt1v5' root/DEBIAN/shlibs ||
  { echo "arm64-ipopt: $(cat root/DEBIAN/shlibs): not the shlibs entry expected" >&2; exit 1; }
dpkg-deb -b -Zxz root "${LOCAL}_arm64.deb" >/dev/null
dpkg -i "${LOCAL}_arm64.deb" >/dev/null
test -e /usr/lib/aarch64-linux-gnu/libipopt.so.1
echo "arm64-ipopt: $LOCAL:arm64 $ver -> /usr/lib/aarch64-linux-gnu/libipopt.so.1"
