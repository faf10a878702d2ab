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
# Everything the parts need, before any part runs: the arm64 builds and the vcan run go side
# by side below, and two apt-gets at once would fight over dpkg's lock.
part "install dependencies"; scripts/install-deps.sh --cross arm64 --package --uml
# The package tests' throwaway Debian roots (downloads and unpacking, no build needed), from
# now on beside the builds: else the command's tail waited on the network for them.
roots_log=$(mktemp); roots_rc=$(mktemp)
( rc=0; nice -n 10 scripts/test-package.sh --prepare >"$roots_log" 2>&1 || rc=$?; echo "$rc" >"$roots_rc" ) &
roots_pid=$!
part "cargo fmt --check"; cargo fmt --all --check
part "import cycles between modules"; python3 scripts/module_cycles.py
# The arm64 part's builds (aarch64 lints, test binaries, the package's binary), in their own
# target directory (scripts/test-arm64.sh), from now on at idle priority: they take only the
# CPU time the parts below leave (their tests wait on real time, the vcan suite's User-mode
# Linux holds one core), and never make those wait. Its output comes after the vcan suite.
arm_log=$(mktemp); arm_build_rc=$(mktemp)
(
  rc=0; chrt --idle 0 nice -n 19 scripts/test-arm64.sh --build >"$arm_log" 2>&1 || rc=$?
  echo "$rc" >"$arm_build_rc"
) &
arm_build_pid=$!
# A process and all it started: to stop the arm64 part when a part fails.
tree() { echo "$1"; for c in $(ps -o pid= --ppid "$1" 2>/dev/null); do tree "$c"; done; }
trap 'for p in $(tree "$roots_pid") $(tree "$arm_build_pid") ${arm_pid:+$(tree "$arm_pid")}; do kill "$p" 2>/dev/null; done' EXIT
part "cargo clippy"; cargo clippy --workspace --all-targets --features vcan,interop -- -D warnings
part "the wire crate without std, for the foot's microcontroller (thumbv7em-none-eabihf)"
cargo build -p presrs-wire --no-default-features --target thumbv7em-none-eabihf
cargo clippy -p presrs-wire --no-default-features --target thumbv7em-none-eabihf -- -D warnings
cargo clippy -p presrs-wire --features alloc --target thumbv7em-none-eabihf -- -D warnings
# With vcan: the vcan suite's binary is built here, with the rest, and its tests listed as
# ignored; tests/vcan/run.sh runs them below, on real SocketCAN.
part "cargo test (unit, property, cantools/python-can interop)"
cargo test --workspace --features interop,vcan
part "vcan suite, the host's part: the test build's binaries, the system tests' model"
tests/vcan/run.sh --prepare
# Where this kernel has no CAN the vcan run is User-mode Linux, one CPU, which run.sh pins to
# core 0 (or a VM). The arm64 part stays on every core at idle priority: User-mode Linux leaves
# about half of its core idle (its processes wait on robot time), and a task at idle priority
# gives way the moment one of them wakes (the run's tests judge robot time).
part "vcan suite (beside it, at idle priority: the rest of scripts/test-arm64.sh, its output after)"
(
  # Once its builds are done (a subshell cannot `wait` for its parent's child: their exit
  # status is in a file), the rest: tests under qemu-aarch64, the packages.
  while [ ! -s "$arm_build_rc" ]; do sleep 2; done
  rc=$(cat "$arm_build_rc"); rm -f "$arm_build_rc"
  [ "$rc" = 0 ] || exit "$rc"
  # The roots too (a failed preparation is tried again, and reported, by the package test).
  while [ ! -s "$roots_rc" ]; do sleep 2; done
  cat "$roots_log"; rm -f "$roots_log" "$roots_rc"
  chrt --idle 0 nice -n 19 scripts/test-arm64.sh >>"$arm_log" 2>&1
) &
arm_pid=$!
vcan_rc=0; tests/vcan/run.sh --prepared || vcan_rc=$?
part "vcan suite done (exit $vcan_rc); the arm64 part beside it:"
arm_rc=0; wait "$arm_pid" || arm_rc=$?
cat "$arm_log"; rm -f "$arm_log"
if [ "$vcan_rc" != 0 ] || [ "$arm_rc" != 0 ]; then
  echo "FAILED: vcan suite exit $vcan_rc, arm64 part exit $arm_rc" >&2
  exit 1
fi
trap - EXIT
part "all tests passed"
