#!/usr/bin/env bash
# Builds the Debian package: target/debian/presrs_<version>_<arch>.deb
#
#   scripts/package-deb.sh --arch amd64|arm64 [--no-build | --binary PATH]
#   scripts/package-deb.sh --print-build-args   the cargo arguments of the binary it builds
#
# The package holds the robot's build of presrs (node, controller, leg, bridge): without the
# `lab` feature, so without the simulator, the experiments and the plots
# (docs/decisions/robot-binary.md); the lab's computer builds the workstation's with `cargo
# build --release`.
# --binary packages an already built presrs for that architecture instead of the robot
# build (the test command packages its test build's binary for amd64: the packaging is what it
# tests; docs/decisions/test-command-time.md, sixth stop).
# arm64 is cross-built on an x86-64 machine with Debian's gcc-aarch64-linux-gnu as the linker
# (installed by scripts/install-deps.sh --cross arm64, with the rustup target). On an arm64
# machine, --arch arm64 builds natively. The package holds:
#   /usr/bin/presrs
#   /lib/systemd/system/presrs-node.service, presrs-controller.service, presrs-leg.service,
#   presrs-bridge.service and their templates presrs-node@.service ... (the interface from the
#   instance name: presrs-node@can1.service; none enabled on install)
#   /usr/share/presrs/ros2/presrs_msgs/ (the ROS 2 interface package, for the ROS side)
#   /etc/presrs/node.toml, controller.toml (conffiles: an edited one survives upgrade and remove)
#   /usr/share/doc/presrs/ (the DBC, README, protocol, deploy and real-robot docs)
# Depends are read off the binary (its NEEDED libraries and the newest glibc symbol version it
# uses), plus procps (/bin/kill for the unit's reload); can-utils and iproute2 are recommended.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

arch=$(dpkg --print-architecture 2>/dev/null || echo amd64)
build=1; given_bin=""
# The robot's build: its default features but the lab's (foxglove: `node --foxglove`).
robot_build=(--bin presrs --no-default-features --features foxglove)
while [ $# -gt 0 ]; do
  case "$1" in
    --print-build-args) echo "${robot_build[*]}"; exit 0 ;;
    --arch) arch="${2:?--arch takes amd64 or arm64}"; shift 2 ;;
    --no-build) build=0; shift ;;
    --binary) given_bin="${2:?--binary takes the path of a built presrs}"; build=0; shift 2 ;;
    -h|--help) sed -n '2,25p' "$0"; exit 0 ;;
    *) echo "package-deb: unknown argument \`$1\` (use --arch amd64|arm64 [--no-build | --binary PATH])" >&2; exit 2 ;;
  esac
done
case "$arch" in
  amd64) triple=x86_64-unknown-linux-gnu; cross_prefix="" ;;
  arm64) triple=aarch64-unknown-linux-gnu; cross_prefix=aarch64-linux-gnu- ;;
  *) echo "package-deb: --arch must be amd64 or arm64, not \`$arch\`" >&2; exit 2 ;;
esac
host_arch=$(dpkg --print-architecture 2>/dev/null || echo amd64)
[ "$arch" = "$host_arch" ] && cross_prefix=""

version=$(cargo metadata --no-deps --format-version 1 |
  python3 -c 'import json,sys; print(next(p["version"] for p in json.load(sys.stdin)["packages"] if p["name"]=="presrs"))')
target_dir=$(cargo metadata --no-deps --format-version 1 |
  python3 -c 'import json,sys; print(json.load(sys.stdin)["target_directory"])')

# The robot's build in its own profile (release settings, target/robot/: the workstation's
# target/release/presrs stays as it is); another architecture is cross-built into
# target/<triple>/robot/.
target_args=(); bin="$target_dir/robot/presrs"
if [ "$arch" != "$host_arch" ]; then
  target_args=(--target "$triple"); bin="$target_dir/$triple/robot/presrs"
fi
if [ "$build" = 1 ]; then
  if [ -n "$cross_prefix" ]; then
    scripts/install-deps.sh --cross "$arch"
    export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER="${cross_prefix}gcc"
  fi
  echo "package-deb: cargo build --profile robot ${target_args[*]} ${robot_build[*]}"
  cargo build --profile robot --quiet "${target_args[@]}" "${robot_build[@]}"
fi
[ -z "$given_bin" ] || bin=$given_bin
[ -x "$bin" ] || { echo "package-deb: no binary at $bin (build it, or drop --no-build / --binary)" >&2; exit 1; }

stage="$target_dir/debian/presrs_${version}_${arch}"
deb="$target_dir/debian/presrs_${version}_${arch}.deb"
rm -rf "$stage"
mkdir -p "$stage/DEBIAN"
# The release profile keeps line tables for profiling; the package ships the stripped binary.
strip="${cross_prefix}strip"
command -v "$strip" >/dev/null || strip=strip
install -D -m 755 "$bin" "$stage/usr/bin/presrs"
"$strip" --strip-debug "$stage/usr/bin/presrs"
# Each part's unit on can0 and its template for any interface (presrs-node@can1.service).
for u in node controller leg bridge; do
  for f in "presrs-$u.service" "presrs-$u@.service"; do
    install -D -m 644 "packaging/systemd/$f" "$stage/lib/systemd/system/$f"
  done
done
for f in package.xml CMakeLists.txt msg/TerrainClass.msg msg/FootContact.msg msg/GaitState.msg; do
  install -D -m 644 "ros2/presrs_msgs/$f" "$stage/usr/share/presrs/ros2/presrs_msgs/$f"
done
install -D -m 644 examples/node.toml "$stage/etc/presrs/node.toml"
install -D -m 644 examples/controller.toml "$stage/etc/presrs/controller.toml"
doc="$stage/usr/share/doc/presrs"
install -D -m 644 packaging/debian/copyright "$doc/copyright"
install -m 644 protocol/presrs.dbc README.md "$doc/"
for f in docs/*.md; do install -m 644 "$f" "$doc/"; done
install -D -m 644 examples/terrains.toml "$doc/examples/terrains.toml"
printf 'presrs (%s) unstable; urgency=medium\n\n  * Built from the presrs workspace.\n\n -- PreSRS developers <presrs@localhost>  %s\n' \
  "$version" "$(date -R -u -d "@${SOURCE_DATE_EPOCH:-$(git log -1 --format=%ct 2>/dev/null || date +%s)}")" |
  gzip -9n > "$doc/changelog.Debian.gz"
for s in postinst prerm postrm; do install -m 755 "packaging/debian/$s" "$stage/DEBIAN/$s"; done
printf '/etc/presrs/node.toml\n/etc/presrs/controller.toml\n' > "$stage/DEBIAN/conffiles"

# Depends from the binary itself: which shared libraries it loads, and the newest glibc
# symbol version it needs (readelf reads any architecture's ELF).
needed=$(readelf -d "$stage/usr/bin/presrs" | sed -n 's/.*Shared library: \[\(.*\)\]/\1/p')
glibc=$(readelf -V "$stage/usr/bin/presrs" | grep -o 'GLIBC_[0-9.]*' | sed 's/GLIBC_//' | sort -V | tail -1)
# procps: the node unit's ExecReload sends SIGHUP with /bin/kill.
depends="libc6 (>= ${glibc:-2.17}), procps"
for lib in $needed; do
  case "$lib" in
    libc.so.6|libm.so.6|libpthread.so.0|libdl.so.2|librt.so.1|ld-linux*) ;;
    libgcc_s.so.1) depends="$depends, libgcc-s1" ;;
    *) echo "package-deb: the binary needs $lib, which this script does not map to a package" >&2; exit 1 ;;
  esac
done
size_kb=$(du -sk --exclude=DEBIAN "$stage" | cut -f1)
cat > "$stage/DEBIAN/control" <<EOF
Package: presrs
Version: $version
Architecture: $arch
Maintainer: PreSRS developers <presrs@localhost>
Installed-Size: $size_kb
Depends: $depends
Recommends: can-utils, iproute2
Section: science
Priority: optional
Description: PreSRS terrain node for legged robots on CAN
 A robot foot's pressure-sensing skin (PreSRS, 44x44 at 100 Hz) streams tactile images on
 CAN FD; the node classifies the terrain once per stance (FFT features, PCA, Parzen window)
 and sends it on the bus, and the controller switches the gait per terrain.
 Includes the robot's presrs (node, controller, leg bridge, ROS 2 bridge), systemd units
 for each, example configs and the CAN database (DBC). Training, discovery and the simulator
 run on the lab's computer (the workstation build).
EOF
dpkg-deb --build --root-owner-group "$stage" "$deb" >/dev/null
echo "package-deb: wrote $deb ($(du -h "$deb" | cut -f1); Depends: $depends)"
