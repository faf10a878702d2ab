#!/usr/bin/env bash
# Installs what the tests need on a fresh Debian machine: Python cantools/python-can (the
# independent CAN clients), can-utils, and for kernels without CAN the VM runner (qemu, a Debian
# kernel with the vcan module, busybox, virtme-ng). Idempotent; quick when all is there.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
sudo=""; [ "$(id -u)" -eq 0 ] || sudo="sudo"

need_apt=()
command -v candump >/dev/null || need_apt+=(can-utils)
if [ "${1:-}" = "--vm" ]; then
  command -v qemu-system-x86_64 >/dev/null || need_apt+=(qemu-system-x86)
  ls /boot/vmlinuz-*-amd64 >/dev/null 2>&1 || need_apt+=(linux-image-amd64)
  [ -x /bin/busybox ] && file -L /bin/busybox 2>/dev/null | grep -q static || need_apt+=(busybox-static)
fi
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "install-deps: apt-get install ${need_apt[*]}"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

py_ok() { python3 -c "import cantools, can, numpy, sklearn" 2>/dev/null; }
if ! py_ok; then
  echo "install-deps: pip install -r tests/requirements.txt"
  python3 -m pip install -q -r "$here/tests/requirements.txt"
fi
if [ "${1:-}" = "--vm" ] && ! command -v vng >/dev/null; then
  echo "install-deps: pip install virtme-ng"
  python3 -m pip install -q virtme-ng
fi
