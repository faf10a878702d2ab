#!/usr/bin/env bash
# Installs what the tests need on a fresh Debian machine: Python cantools/python-can (the
# independent CAN clients), eclipse-zenoh and rosbags (the ROS 2 clients), jiku-data (real plantar-pressure images for the open-set test),
# can-utils, and for kernels without CAN a kernel that has it. Idempotent; quick when all is
# there.
#   --uml          also User-mode Linux (Debian's user-mode-linux: a kernel with vcan that runs
#                  as a program; tests/vcan/run.sh's default where this kernel has no CAN)
#   --vm           also the VM runner (qemu, a Debian kernel with the vcan module, busybox,
#                  virtme-ng; PRESRS_VCAN_RUNNER=vng)
#   --cross arm64  also the arm64 cross toolchain (Debian's gcc-aarch64-linux-gnu, qemu-user to
#                  run its binaries, the rustup target aarch64-unknown-linux-gnu)
#   --package      also what tests the Debian package (debootstrap, for a throwaway root)
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
sudo=""; [ "$(id -u)" -eq 0 ] || sudo="sudo"

vm=0; uml=0; cross=""; package=0
while [ $# -gt 0 ]; do
  case "$1" in
    --vm) vm=1; shift ;;
    --uml) uml=1; shift ;;
    --cross) cross="${2:?--cross takes arm64}"; shift 2 ;;
    --package) package=1; shift ;;
    *) echo "install-deps: unknown argument \`$1\` (use --uml, --vm, --cross arm64, --package)" >&2; exit 2 ;;
  esac
done
need_apt=()
command -v candump >/dev/null || need_apt+=(can-utils)
if [ "$cross" = arm64 ]; then
  command -v aarch64-linux-gnu-gcc >/dev/null || need_apt+=(gcc-aarch64-linux-gnu libc6-dev-arm64-cross)
  command -v qemu-aarch64 >/dev/null || need_apt+=(qemu-user)
elif [ -n "$cross" ]; then
  echo "install-deps: --cross knows arm64, not \`$cross\`" >&2; exit 2
fi
if [ "$package" = 1 ]; then
  command -v debootstrap >/dev/null || need_apt+=(debootstrap)
  command -v systemd-analyze >/dev/null || need_apt+=(systemd)
fi
if [ "$uml" = 1 ]; then
  command -v linux.uml >/dev/null || need_apt+=(user-mode-linux)
  # Its init loads vcan with insmod, which a fresh Debian without a kernel image lacks.
  command -v insmod >/dev/null || need_apt+=(kmod)
  # tests/vcan/uml-xstate.c, preloaded into it on hosts with AMX, is compiled by the run.
  command -v cc >/dev/null || need_apt+=(gcc libc6-dev)
fi
if [ "$vm" = 1 ]; then
  command -v qemu-system-x86_64 >/dev/null || need_apt+=(qemu-system-x86)
  ls /boot/vmlinuz-*-amd64 >/dev/null 2>&1 || need_apt+=(linux-image-amd64)
  [ -x /bin/busybox ] && file -L /bin/busybox 2>/dev/null | grep -q static || need_apt+=(busybox-static)
fi
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "install-deps: apt-get install ${need_apt[*]}"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

py_ok() { python3 -c "import cantools, can, numpy, sklearn, mcap, websockets, jikudata, zenoh, rosbags" 2>/dev/null; }
if ! py_ok; then
  echo "install-deps: pip install -r tests/requirements.txt"
  python3 -m pip install -q -r "$here/tests/requirements.txt"
fi
# The foot's firmware build of the protocol crate (no_std, Cortex-M4F).
if ! rustup target list --installed | grep -qx thumbv7em-none-eabihf; then
  echo "install-deps: rustup target add thumbv7em-none-eabihf"
  rustup target add thumbv7em-none-eabihf
fi
if [ "$cross" = arm64 ] && ! rustup target list --installed | grep -qx aarch64-unknown-linux-gnu; then
  echo "install-deps: rustup target add aarch64-unknown-linux-gnu"
  rustup target add aarch64-unknown-linux-gnu
fi
if [ "$vm" = 1 ] && ! command -v vng >/dev/null; then
  echo "install-deps: pip install virtme-ng"
  python3 -m pip install -q virtme-ng
fi
