#!/usr/bin/env bash
# Runs the vcan suite (tests/vcan.rs) on real SocketCAN interfaces:
# - directly, where this kernel can create vcan interfaces (a laptop, a robot, a CI runner with
#   linux-modules-extra);
# - otherwise inside User-mode Linux (Debian's kernel as a program, with vcan; ~5 s to boot),
#   or, with PRESRS_VCAN_RUNNER=vng, a virtme-ng VM under TCG emulation. The test binary is
#   built here and run there.
# Prints how many vcan tests passed; zero is a failure, never a skip.
#
#   tests/vcan/run.sh              build, then run
#   tests/vcan/run.sh --prepare    only the host's part (the test build's binaries, the system
#                                  tests' model); what the run needs goes to a file
#   tests/vcan/run.sh --prepared   only the run, from that file: it builds nothing, so
#                                  ./test-all.sh builds the arm64 part beside it
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
mode=all
case "${1:-}" in
  "") ;;
  --prepare) mode=prepare ;;
  --prepared) mode=prepared ;;
  *) echo "vcan suite: unknown argument \`$1\` (use --prepare, --prepared, or none)" >&2; exit 2 ;;
esac
# Wherever cargo puts its output (CARGO_TARGET_DIR, a config's build.target-dir, or ./target):
# a stale binary must not run, and --prepared must find what --prepare wrote. `cargo metadata
# --no-deps` only reads the manifests: it builds nothing and waits for no build beside it
# (measured: 0.3 s while the arm64 build ran).
target_dir=$(cargo metadata --no-deps --offline --format-version 1 |
  python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
work="$target_dir/vcan-system"
prepared="$work/prepared.env"

prepare() {
  # The binaries ./test-all.sh's `cargo test` built (nothing rebuilt after it): the suite, the
  # `presrs` the CLI tests run and the foot_firmware example. The dev profile optimises the
  # simulator, the node and their numeric crates (Cargo.toml), which keeps the processes on
  # robot time in the VM; a release build of its own cost the test command ~600 s (clean-clone
  # run of 2026-11-28) and the suite ran green on both (docs/decisions/test-command-time.md).
  echo "vcan suite: the test binary, presrs and the firmware example of the test build (at $SECONDS s)"
  bin=$(scripts/test-exe.sh vcan)
  PRESRS_BIN=$(scripts/test-exe.sh presrs bin)
  PRESRS_FIRMWARE=$(scripts/test-exe.sh foot_firmware example)

  # The system tests run `presrs lab sim/node/controller` as processes; the node needs a model
  # trained on simulated G2 stances.
  echo "vcan suite: training the system tests' G2 model (at $SECONDS s)"
  if [ ! -s "$work/g2-model.json" ] || [ "$PRESRS_BIN" -nt "$work/g2-model.json" ]; then
    rm -rf "$work" && mkdir -p "$work"
    "$PRESRS_BIN" lab dataset dynamic --gait G2 --n 60 --seed 21 --out "$work/g2" >/dev/null
    # Its unknown-terrain rejection calibrated on a second run of the robot (30 s of the closed
    # loop, captured as a lab would): calibrated on the training set's own unused images, the
    # closed loop's stances after a terrain change fell outside often enough that G3 was 62/67
    # right in the VM (measured; the host replica with this calibration: 57-59/59 G1, 58-61/61
    # G2, 66-68/68 G3 over sim seeds 5-8).
    "$PRESRS_BIN" lab sim --gait G2 --log "$work/cal.log" --truth "$work/cal.csv" --duration 30 \
      --seed 22 >/dev/null 2>&1
    "$PRESRS_BIN" capture --replay "$work/cal.log" --labels "$work/cal.csv" --out "$work/cal" >/dev/null
    # Its checks fixed (`--unknown-checks`), not chosen: these tests' bounds (steps to a gait,
    # accuracy per step) were measured with this model's, and a 30 s calibration run is too
    # short for `train` to choose on (it said so: no candidate within its budget). The choice
    # is tested in node's unit tests and tests/open_set.rs.
    "$PRESRS_BIN" train --data "$work/g2" --out "$work/g2-model.json" --crop 0,3,6,0 \
      --per-class 45 --train 30 --normalize-load --seed 21 --calibrate "$work/cal" \
      --unknown-checks knn-residual,normalize-load
  fi
  # cantools parses presrs.dbc once, here (3.7 s), into a cache the VM's tests load in seconds;
  # parsed inside the VM it took most of a minute per test that decodes a candump log.
  PRESRS_DBC_CACHE="$work/dbc-cache"
  PRESRS_DBC_CACHE="$PRESRS_DBC_CACHE" python3 tests/interop/cantools_check.py log protocol/presrs.dbc /dev/null >/dev/null
  {
    echo "bin='$bin'"
    echo "PRESRS_BIN='$PRESRS_BIN'"
    echo "PRESRS_MODEL='$work/g2-model.json'"
    echo "PRESRS_FIRMWARE='$PRESRS_FIRMWARE'"
    echo "PRESRS_DBC_CACHE='$PRESRS_DBC_CACHE'"
  } > "$prepared"
}

if [ "$mode" != prepared ]; then
  prepare
  [ "$mode" = prepare ] && { echo "vcan suite: prepared (at $SECONDS s): $prepared"; exit 0; }
fi
[ -s "$prepared" ] || { echo "vcan suite: nothing prepared at $prepared (run tests/vcan/run.sh --prepare first)" >&2; exit 1; }
# shellcheck source=/dev/null
. "$prepared"
export PRESRS_BIN PRESRS_MODEL PRESRS_FIRMWARE PRESRS_DBC_CACHE

# PRESRS_VCAN_FILTER: a test-name filter for the vcan binary (while developing; CI runs all).
log=$(mktemp)
can_here() {
  [ "$(id -u)" -eq 0 ] || return 1
  python3 -c 'import socket; socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)' 2>/dev/null || return 1
  modprobe vcan 2>/dev/null || true
  ip link add dev presrs-probe0 type vcan 2>/dev/null && ip link del dev presrs-probe0
}

# PRESRS_VCAN_RUNNER: where the suite runs when this kernel has no CAN: `uml` (the default) or
# `vng` (a virtme-ng VM under qemu TCG, the runner before 2026-11-26; still here for a host where
# User-mode Linux cannot run, e.g. one that forbids ptrace).
runner=${PRESRS_VCAN_RUNNER:-uml}
# Debian's User-mode Linux 6.1 restores its processes' FP registers in a buffer sized for
# AVX-512, which a host with AMX refuses ("ptrace set fp regs failed, errno = 14": its init
# dies at once; seen on 2026-11-27 CI machines). tests/vcan/uml-xstate.c, preloaded into it,
# hands the host the whole XSAVE area (a no-op where the sizes agree). A 5 s boot that must
# print a marker tells whether it runs; where it does not (e.g. a host that forbids ptrace),
# the suite runs in the virtme-ng VM instead (slower, but it runs).
uml_preload=()
uml_shim() {
  [ "${#uml_preload[@]}" -gt 0 ] && return 0
  mkdir -p "$work"
  cc -shared -fPIC -O2 -Wall -o "$work/uml-xstate.so" "$root/tests/vcan/uml-xstate.c" -ldl || return 1
  uml_preload=(env LD_PRELOAD="$work/uml-xstate.so")
}
uml_boots() {
  "$root/scripts/install-deps.sh" --uml >/dev/null
  uml_shim || return 1
  local probe="$work/uml-probe.sh"
  printf '#!/bin/sh\necho PRESRS-UML-BOOTED\nhalt -f\n' > "$probe"
  chmod +x "$probe"
  timeout --kill-after 5 30 "${uml_preload[@]}" linux.uml mem=256M quiet root=/dev/root rootfstype=hostfs rootflags=/ \
    rw init="$probe" con=null con0=fd:0,fd:1 < /dev/null 2>&1 | grep -q PRESRS-UML-BOOTED
}
if [ "$runner" = uml ] && [ -z "${PRESRS_VCAN_RUNNER:-}" ] && ! can_here && ! uml_boots; then
  echo "vcan suite: User-mode Linux does not boot on this host (with tests/vcan/uml-xstate.c preloaded); running the suite in a virtme-ng VM instead (about twice as long)"
  runner=vng
fi
# What the tests need from the host, for a guest kernel's shell (User-mode Linux or the VM).
guest_env="export PATH='$PATH' HOME='$HOME' PRESRS_BIN='$PRESRS_BIN' PRESRS_MODEL='$PRESRS_MODEL' PRESRS_FIRMWARE='$PRESRS_FIRMWARE' PRESRS_DBC_CACHE='$PRESRS_DBC_CACHE'"
if [ "${PRESRS_VCAN_FORCE_VM:-0}" != 1 ] && can_here; then
  where="on this kernel"
  export PRESRS_BENCH_LABEL="vcan on this kernel"
  tests/vcan/lanes.sh "$bin" "${PRESRS_VCAN_FILTER:-}" 2>&1 | tee "$log"
elif [ "$runner" = uml ]; then
  where="inside User-mode Linux (this kernel has no CAN: AF_CAN unavailable)"
  # User-mode Linux: Debian's kernel built as a Linux program (package user-mode-linux), with
  # the host's root as its root (hostfs) and vcan as a module. Its processes run natively and
  # only their system calls go through its kernel: the same 12 s G1 run of sim and node took
  # 19.4 s asked at full speed (39.4 s asked at 0.35) against 51-53 s at 0.35 in the TCG VM,
  # which also needed 20 s to boot where this needs 5 (2026-11-26, this 2-core machine). The
  # whole suite: 662 s here (clean clone, with the arm64 builds on the other core) against
  # 1247 s in the VM.
  "$root/scripts/install-deps.sh" --uml
  uml_shim
  init="$work/uml-init.sh"
  # A tmpfs on /tmp keeps the tests' scratch files off hostfs, but it hides the host's /tmp:
  # a checkout (or its target directory) under /tmp then cannot be reached ("can't cd").
  # There the host's /tmp stays as it is.
  tmp_mount="mount -t tmpfs tmpfs /tmp"
  for p in "$root" "$work" "$bin" "$PRESRS_BIN" "$PRESRS_MODEL" "$PRESRS_FIRMWARE" "$PRESRS_DBC_CACHE"; do
    case "$p" in /tmp|/tmp/*) tmp_mount=": the checkout is under /tmp: the host's /tmp stays visible" ;; esac
  done
  cat > "$init" <<INIT
#!/bin/sh
# PID 1 of the User-mode Linux run (written by tests/vcan/run.sh): never exits but by halt.
mount -t proc proc /proc; mount -t sysfs sys /sys; $tmp_mount
mkdir -p /dev/shm && mount -t tmpfs tmpfs /dev/shm
# What udev would make: bash's process substitution reads /dev/fd/N.
ln -sf /proc/self/fd /dev/fd
mods=/usr/lib/uml/modules/\$(uname -r)/kernel
for m in net/can/can net/can/can-raw drivers/net/can/dev/can-dev drivers/net/can/vcan; do
  insmod "\$mods/\$m.ko" || echo "uml: could not load \$m.ko from \$mods"
done
if ! grep -q '^vcan ' /proc/modules; then
  # Nothing can run without it: say why at once rather than let every test wait for a bus.
  echo "uml: vcan is not loaded (insmod: \$(command -v insmod || echo 'not found: install kmod'); scripts/install-deps.sh --uml installs it)"
  echo "VCAN_SUMMARY passed=0 failed=0 expected=0 exit=1"
  halt -f
fi
$guest_env
# The robot's clock at half the wall clock, the leg and the fault drill at 0.35, the bench
# with one foot: what this kernel carries (tests/vcan/lanes.sh and tests/vcan.rs say what was
# measured).
export PRESRS_SYSTEM_SPEED='${PRESRS_SYSTEM_SPEED:-0.5}' PRESRS_SLOW_SPEED='${PRESRS_SLOW_SPEED:-0.35}'
export PRESRS_BENCH_FEET='${PRESRS_BENCH_FEET:-1}'
export PRESRS_BENCH_LABEL='User-mode Linux: vcan in a UML kernel, one CPU'
if ! cd '$root'; then
  echo "uml: cannot enter the checkout $root inside User-mode Linux"
  echo "VCAN_SUMMARY passed=0 failed=0 expected=0 exit=1"
  halt -f
fi
tests/vcan/lanes.sh '$bin' '${PRESRS_VCAN_FILTER:-}'
halt -f
INIT
  chmod +x "$init"
  # On one host core where there are two or more: its processes hand every system call to its
  # kernel (ptrace), and across cores each hand-over is a wake-up on the other core. Beside an
  # aarch64 build on the other core (2026-11-26, 2-core machine), unpinned: the MIT leg fell
  # at 0.35 and the fault drill's node restart took 1.38 robot s of its 1.5; pinned: no fall,
  # the leg's test 111 s against 133 s unpinned and unloaded, the restart 0.64 robot s.
  pin=(); [ "$(nproc)" -ge 2 ] && pin=(taskset -c 0)
  echo "vcan suite: booting User-mode Linux ${pin[*]:+(${pin[*]}) }(at $SECONDS s)"
  set +e
  timeout --kill-after 30 2700 "${pin[@]}" "${uml_preload[@]}" linux.uml mem=2G quiet root=/dev/root rootfstype=hostfs rootflags=/ \
    rw init="$init" con=null con0=fd:0,fd:1 < /dev/null 2>&1 | sed -u 's/\r$//' | tee "$log"
  set -e
elif [ "$runner" = vng ]; then
  where="inside a virtme-ng VM (this kernel has no CAN: AF_CAN unavailable)"
  # TCG emulation cannot keep real time, so the system tests run the robot's clock at 0.35 of
  # the wall clock (the simulator, node and controller all follow it; the simulator reaches
  # about 0.23). The suite took 1247 s in the VM in the clean-clone run of 2026-11-26 (14 tests,
  # alone and in lanes; 1261 s one at a time before). The VM gets 45 min; a loaded host once
  # stretched it past a 20 min limit.
  "$root/scripts/install-deps.sh" --vm
  kernel=$(ls /boot/vmlinuz-*-amd64 | sort -V | tail -1)
  echo "vcan suite: booting $kernel under TCG (KVM unavailable here; at $SECONDS s)"
  # 4 vCPUs on a 2-core host: the guest's tests wait on its timers more than they compute, and
  # the second lane of tests/vcan/lanes.sh needs vCPUs to wait on (two 12 s G1 runs at once:
  # 75 s with 2 vCPUs, 64 s with 4; one alone 51-53 s with either).
  set +e
  timeout 2700 vng -r "$kernel" --user root --disable-kvm --cpus 4 --memory 2G \
    --exec "$guest_env
export PRESRS_SYSTEM_SPEED='${PRESRS_SYSTEM_SPEED:-0.35}'
export PRESRS_BENCH_LABEL='emulated: vcan inside a TCG VM, 4 vCPUs on 2 host cores'
cd '$root' && tests/vcan/lanes.sh '$bin' '${PRESRS_VCAN_FILTER:-}'" 2>&1 | tee "$log"
  set -e
else
  echo "vcan suite: PRESRS_VCAN_RUNNER is \`$runner\`; use uml (User-mode Linux) or vng (virtme-ng VM)" >&2
  exit 2
fi

summary=$(grep -a -o 'VCAN_SUMMARY .*' "$log" | tail -1)
num() { echo "$summary" | grep -o "$1=[0-9]*" | cut -d= -f2; }
passed=$(num passed); failed=$(num failed); expected=$(num expected); rc=$(num exit)
passed=${passed:-0}; failed=${failed:-0}; expected=${expected:-0}; rc=${rc:-1}
echo "vcan suite $where: $passed passed, $failed failed, of $expected (at $SECONDS s)"
rm -f "$log"
# A test that no phase ran (or a phase that died) counts as a failure, as does an empty run.
if [ "$passed" -lt "$expected" ]; then rc=1; fi
if [ "$rc" != 0 ] || [ "$passed" -eq 0 ]; then
  echo "vcan suite: FAILED (exit $rc, $passed passed)" >&2
  exit 1
fi
