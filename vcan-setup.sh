#!/usr/bin/env bash
# Bring up virtual CAN interfaces for the PreSRS node, tests and demos.
#
#   sudo ./vcan-setup.sh                 vcan0, CAN FD capable (MTU 72)
#   sudo ./vcan-setup.sh vcan0 vcan1     several interfaces
#   sudo ./vcan-setup.sh --classic vcan1 classic CAN only (MTU 16): FD frames are rejected
#   sudo ./vcan-setup.sh --down [IFACE...]  remove them
#
# Idempotent: an interface that exists is reconfigured, not recreated.
set -euo pipefail

mtu=72
down=0
ifaces=()
for a in "$@"; do
  case "$a" in
    --classic) mtu=16 ;;
    --down) down=1 ;;
    -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
    -*) echo "vcan-setup.sh: unknown option $a (see --help)" >&2; exit 2 ;;
    *) ifaces+=("$a") ;;
  esac
done
[ ${#ifaces[@]} -gt 0 ] || ifaces=(vcan0)

if [ "$(id -u)" -ne 0 ]; then
  echo "vcan-setup.sh: creating network interfaces needs root: run it with sudo." >&2
  exit 1
fi

if [ "$down" -eq 1 ]; then
  for i in "${ifaces[@]}"; do
    if ip link show "$i" >/dev/null 2>&1; then ip link del dev "$i"; echo "$i removed"; fi
  done
  exit 0
fi

if ! modprobe vcan 2>/dev/null && ! [ -d /sys/module/vcan ]; then
  if ! ip link add dev presrs-probe0 type vcan 2>/dev/null; then
    cat >&2 <<MSG
vcan-setup.sh: this kernel has no virtual CAN (vcan) support: 'modprobe vcan' failed and
'ip link add ... type vcan' is refused. On Debian/Ubuntu the module is in linux-modules-extra
(apt-get install linux-modules-extra-\$(uname -r)); in containers and sandboxes whose kernel has
no CAN at all (socket(AF_CAN) fails with errno 97), run the vcan suite on a kernel of its own:
    tests/vcan/run.sh        (boots User-mode Linux, a kernel with vcan run as a program)
MSG
    exit 1
  fi
  ip link del dev presrs-probe0
fi

for i in "${ifaces[@]}"; do
  if ! ip link show "$i" >/dev/null 2>&1; then
    ip link add dev "$i" type vcan
  fi
  ip link set "$i" down
  ip link set "$i" mtu "$mtu"
  ip link set "$i" up
  echo "$i up, MTU $mtu ($([ "$mtu" = 72 ] && echo 'CAN FD' || echo 'classic CAN only'))"
done
