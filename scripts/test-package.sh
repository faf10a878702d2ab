#!/usr/bin/env bash
# Tests the Debian packages that scripts/package-deb.sh wrote, in throwaway Debian roots made
# with debootstrap (minbase of this machine's release plus what a robot's computer has: systemd,
# procps, iproute2; cached under target/deb-test/):
# - amd64: `dpkg -i` into a fresh root (its Depends met by the root's own packages), the
#   binary runs there, `systemd-analyze verify` accepts both units, an edited conffile and the
#   user's model survive remove and reinstall, purge removes the rest and keeps the model;
# - arm64: the root gets arm64 as a foreign architecture and Debian's libc6:arm64 and
#   libgcc-s1:arm64, `dpkg -i` installs the arm64 package there, and its /usr/bin/presrs (the
#   robot's build), run under qemu-aarch64 with that root's libraries, decides every step of a
#   simulated run's candump log as the x86-64 node does.
#
#   scripts/test-package.sh [--x86 PATH]   PATH: the x86-64 presrs to compare with (the test
#                                          command's test build); without it, the release build
#   scripts/test-package.sh --prepare      only the roots (downloads and unpacking, no package
#                                          needed): ./test-all.sh runs it at its start, beside
#                                          the builds, so that the test command's tail does not
#                                          wait on the network
set -euo pipefail
x86=""; prepare_only=0
case "${1:-}" in
  "") ;;
  --x86) x86="${2:?--x86 takes the path of an x86-64 presrs}" ;;
  --prepare) prepare_only=1 ;;
  *) echo "test-package: unknown argument \`$1\` (use --x86 PATH, --prepare, or none)" >&2; exit 2 ;;
esac
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
[ "$(id -u)" -eq 0 ] || { echo "test-package: needs root (chroot, debootstrap)" >&2; exit 1; }

meta=$(cargo metadata --no-deps --format-version 1)
version=$(python3 -c 'import json,sys; print(next(p["version"] for p in json.load(sys.stdin)["packages"] if p["name"]=="presrs"))' <<<"$meta")
target_dir=$(python3 -c 'import json,sys; print(json.load(sys.stdin)["target_directory"])' <<<"$meta")
amd="$target_dir/debian/presrs_${version}_amd64.deb"
arm="$target_dir/debian/presrs_${version}_arm64.deb"
if [ "$prepare_only" = 0 ]; then
  for d in "$amd" "$arm"; do
    [ -s "$d" ] || { echo "test-package: $d is missing: run scripts/package-deb.sh --arch amd64 and arm64" >&2; exit 1; }
  done
fi

fail() { echo "test-package: FAILED: $*" >&2; exit 1; }
work="$target_dir/deb-test"
codename=$(. /etc/os-release && echo "${VERSION_CODENAME:-bookworm}")
base="$work/base-$codename-systemd"
if [ ! -e "$base/.complete" ]; then
  echo "test-package: debootstrap --variant=minbase $codename (a throwaway root)"
  rm -rf "$base"; mkdir -p "$work"
  debootstrap --variant=minbase --include=systemd,procps,iproute2 "$codename" "$base" \
    >"$work/debootstrap.log" 2>&1 ||
    { tail -20 "$work/debootstrap.log" >&2; fail "debootstrap (log: $work/debootstrap.log)"; }
  touch "$base/.complete"
fi
# A fresh copy of root $2 (the base by default) at $1.
fresh() { rm -rf "$1"; cp -a "${2:-$base}" "$1"; cp /etc/resolv.conf "$1/etc/resolv.conf"; }
in_root() { local r=$1; shift; chroot "$r" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin LC_ALL=C "$@"; }
# The arm64 root before the package: arm64 a foreign architecture, Debian's arm64 libc in it.
arm_base="$work/base-$codename-arm64"
if [ ! -e "$arm_base/.complete" ]; then
  fresh "$arm_base"; rm -f "$arm_base/.complete"
  in_root "$arm_base" dpkg --add-architecture arm64
  in_root "$arm_base" apt-get update -qq >/dev/null || fail "apt-get update in the arm64 root"
  in_root "$arm_base" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
    libc6:arm64 libgcc-s1:arm64 >/dev/null || fail "installing libc6:arm64 libgcc-s1:arm64 in the root"
  touch "$arm_base/.complete"
fi
if [ "$prepare_only" = 1 ]; then
  echo "test-package: the $codename roots are ready ($work)"
  exit 0
fi

# ---- amd64: install, run, verify the units, conffiles across remove/reinstall/purge
r="$work/root-amd64"; fresh "$r"
cp "$amd" "$r/tmp/presrs.deb"
in_root "$r" dpkg -i /tmp/presrs.deb >/dev/null || fail "dpkg -i $(basename "$amd") into a fresh root"
in_root "$r" presrs --help >/dev/null || fail "the installed presrs does not run in the fresh root"
for f in /usr/bin/presrs /etc/presrs/node.toml /etc/presrs/controller.toml \
         /lib/systemd/system/presrs-node.service /lib/systemd/system/presrs-leg.service \
         /lib/systemd/system/presrs-bridge.service /usr/share/presrs/ros2/presrs_msgs/msg/TerrainClass.msg \
         /usr/share/doc/presrs/presrs.dbc; do
  [ -e "$r$f" ] || fail "$f not installed"
done
# verify resolves ExecStart= and the units' dependencies inside the root.
systemd-analyze verify --root="$r" presrs-node.service presrs-controller.service presrs-leg.service presrs-bridge.service ||
  fail "systemd-analyze verify rejects the units"
# The templates, for the interface each instance names (can0 and can1).
for i in can0 can1; do
  units=()
  for u in node controller leg bridge; do
    [ -e "$r/lib/systemd/system/presrs-$u@.service" ] || fail "presrs-$u@.service not installed"
    units+=("presrs-$u@$i.service")
  done
  systemd-analyze verify --root="$r" "${units[@]}" || fail "systemd-analyze verify rejects the $i instances"
done
echo "# edited on the robot" >> "$r/etc/presrs/node.toml"
echo '{"user": "model"}' > "$r/etc/presrs/model.json"
in_root "$r" dpkg -r presrs >/dev/null || fail "dpkg -r presrs"
[ ! -e "$r/usr/bin/presrs" ] || fail "remove left /usr/bin/presrs"
grep -q "edited on the robot" "$r/etc/presrs/node.toml" || fail "remove lost the edited node.toml"
in_root "$r" dpkg -i /tmp/presrs.deb >/dev/null </dev/null || fail "reinstall after remove"
grep -q "edited on the robot" "$r/etc/presrs/node.toml" || fail "reinstall overwrote the edited node.toml"
in_root "$r" dpkg -P presrs >/dev/null || fail "dpkg -P presrs"
[ ! -e "$r/etc/presrs/controller.toml" ] || fail "purge left controller.toml"
[ -e "$r/etc/presrs/model.json" ] || fail "purge removed the user's model"
echo "test-package: amd64: installs into a fresh $codename root, runs, units and their can0/can1 instances verify, edited config kept on remove and reinstall, purge keeps the model"

# ---- arm64: a root with Debian's arm64 libc, the package installed there, its binary run
r="$work/root-arm64"; fresh "$r" "$arm_base"
cp "$arm" "$r/tmp/presrs.deb"
in_root "$r" dpkg -i /tmp/presrs.deb >/dev/null || fail "dpkg -i $(basename "$arm") into the arm64 root"
[ "$(in_root "$r" dpkg-query -W -f='${Architecture} ${Status}' presrs)" = "arm64 install ok installed" ] ||
  fail "presrs:arm64 is not installed in the root"
file_arch=$(readelf -h "$r/usr/bin/presrs" | sed -n 's/.*Machine: *//p')
[ "$file_arch" = "AArch64" ] || fail "the installed binary is $file_arch, not AArch64"
arm_presrs=(qemu-aarch64 -L "$r" "$r/usr/bin/presrs")
"${arm_presrs[@]}" --help >/dev/null || fail "the arm64 presrs does not start under qemu-aarch64"

# The same terrain from both binaries for every image: models and data made on x86-64.
if [ -z "$x86" ]; then
  cargo build --release --quiet --bin presrs
  x86="$target_dir/release/presrs"
fi
data="$work/data"; rm -rf "$data"; mkdir -p "$data"
# The package's binary is the robot's build: no dataset, train or demo in it. The x86-64 one
# makes the model and the run; the installed arm64 node decides the run as the x86-64 node does.
"$x86" lab dataset dynamic --gait G2 --out "$data/g2" --seed 3 >/dev/null
"$x86" train --data "$data/g2" --out "$data/g2.json" >/dev/null
"$x86" demo --steps 60 --seed 3 --candump "$data/demo.log" >/dev/null 2>&1 ||
  fail "the x86-64 demo did not write its candump log"
replay=(node --replay "$data/demo.log" --model "$data/g2.json" --json)
"$x86" "${replay[@]}" > "$data/replay.x86_64.jsonl" 2>/dev/null || fail "x86-64 node --replay"
"${arm_presrs[@]}" "${replay[@]}" > "$data/replay.aarch64.jsonl" 2>/dev/null ||
  fail "the arm64 node does not replay the log (node --replay)"
python3 - "$data/replay.x86_64.jsonl" "$data/replay.aarch64.jsonl" <<'PY' || fail "arm64 and x86-64 nodes decide the run differently"
import json, sys
a = [json.loads(l) for l in open(sys.argv[1])]
b = [json.loads(l) for l in open(sys.argv[2])]
assert len(a) == len(b) and len(a) >= 30, f"{len(a)} vs {len(b)} decisions"
# Every field the same but the floats, within 1e-3 (the NEON and x86-64 kernels sum in
# another order); an unknown step has no confidence on both.
def differs(x, y):
    if isinstance(x, float) or isinstance(y, float):
        return x is None or y is None or abs(float(x) - float(y)) > 1e-3
    if isinstance(x, dict) and isinstance(y, dict):
        return x.keys() != y.keys() or any(differs(x[k], y[k]) for k in x)
    return x != y
bad = [(i, x, y) for i, (x, y) in enumerate(zip(a, b)) if differs(x, y)]
known = sum(1 for x in a if x.get("terrain") not in (None, "unknown"))
# A run decided all unknown would compare nothing of the classifier: most steps are known.
assert known >= len(a) // 3, f"only {known} of {len(a)} decisions name a terrain"
print(f"test-package: node --replay: {len(a)} decisions ({known} of a known terrain), "
      f"{len(a) - len(bad)} the same on arm64 (qemu) and x86-64")
for i, x, y in bad[:5]:
    print("  differs at", i, x, y)
sys.exit(1 if bad else 0)
PY
for c in node controller leg bridge; do
  "${arm_presrs[@]}" "$c" --help >/dev/null || fail "the arm64 presrs has no $c"
done
# The robot's build says where the lab's commands are, and stops.
if "${arm_presrs[@]}" train --help >/dev/null 2>"$data/train.err"; then fail "the arm64 presrs runs train: not the robot's build"; fi
grep -q "workstation build" "$data/train.err" || fail "the arm64 presrs's train error does not say where train is"
echo "test-package: arm64: installs with Debian's arm64 libc; its robot build (node, controller, leg, bridge; no lab commands) decides a run as the x86-64 node does"
