#!/usr/bin/env bash
# Every test: format, lints, unit/property/interop tests, the arm64 build with its Debian
# packages, and the vcan suite on real SocketCAN (inside a VM when this kernel has no CAN).
# Installs what it needs first. Each part prints its wall time.
set -euo pipefail
cd "$(dirname "$0")"
t0=$SECONDS
# The free disk with each part: a CI machine ran out mid-build once (target/ grew to 12 GB).
part() { echo "== $1 (at $((SECONDS - t0)) s; $(df -h --output=avail . | tail -1 | tr -d ' ') free)"; }
# One clean build per run: incremental caches only cost disk and time here.
export CARGO_INCREMENTAL=0
# (The VM's packages, where this kernel has no CAN, come with tests/vcan/run.sh --prepare.)
part "install dependencies"; scripts/install-deps.sh --cross arm64 --package
part "cargo fmt --check"; cargo fmt --all --check
part "cargo clippy"; cargo clippy --workspace --all-targets --features vcan,interop -- -D warnings
part "protocol without std, for the foot's microcontroller (thumbv7em-none-eabihf)"
cargo build -p presrs-protocol --no-default-features --target thumbv7em-none-eabihf
cargo clippy -p presrs-protocol --no-default-features --target thumbv7em-none-eabihf -- -D warnings
part "cargo test (unit, property, cantools/python-can interop)"
cargo test --workspace --features interop
part "vcan suite, the host's part: the test binary, the release build, the system tests' model"
tests/vcan/run.sh --prepare
# The VM's tests run on the robot's clock, at a fixed fraction of the wall clock, and leave
# some CPU idle: the arm64 part's builds (cross builds, both packages' binaries) take it at the
# lowest priority, so the VM's processes get theirs first; its tests run after the VM, alone.
# In sequence the two parts took 1039 s and 1488 s of a 3141 s run (clean clone, 2-core
# machine, 2026-11-25).
arm_log=$(mktemp)
part "vcan suite (beside it at nice 19: scripts/test-arm64.sh --build, its output after)"
nice -n 19 scripts/test-arm64.sh --build >"$arm_log" 2>&1 &
arm_pid=$!
vcan_rc=0; tests/vcan/run.sh --prepared || vcan_rc=$?
part "vcan suite done (exit $vcan_rc); the arm64 builds beside it:"
arm_rc=0; wait "$arm_pid" || arm_rc=$?
cat "$arm_log"; rm -f "$arm_log"
if [ "$vcan_rc" != 0 ] || [ "$arm_rc" != 0 ]; then
  echo "FAILED: vcan suite exit $vcan_rc, arm64 builds exit $arm_rc" >&2
  exit 1
fi
part "arm64: tests under qemu-aarch64, Debian packages"; scripts/test-arm64.sh
part "all tests passed"
