#!/usr/bin/env bash
# Every test: format, lints, unit/property/interop tests, the arm64 build with its Debian
# packages, and the vcan suite on real SocketCAN (inside a VM when this kernel has no CAN).
# Installs what it needs, beside the first lints. Each part prints its wall time.
set -euo pipefail
cd "$(dirname "$0")"
t0=$SECONDS
# The free disk with each part: a CI machine ran out mid-build once (target/ grew to 12 GB).
part() { echo "== $1 (at $((SECONDS - t0)) s; $(df -h --output=avail . | tail -1 | tr -d ' ') free)"; }
# One clean build per run: incremental caches only cost disk and time here.
export CARGO_INCREMENTAL=0
# What the parts need (Debian's packages, Python clients, Rust targets) installs beside the
# host's lints, which need none of it: on a fresh machine the install took minutes that
# clippy now fills. One install, before anything else that uses apt: two apt-gets at once
# would fight over dpkg's lock.
deps_log=$(mktemp); deps_rc=$(mktemp)
( rc=0; scripts/install-deps.sh --cross arm64 --package --uml >"$deps_log" 2>&1 || rc=$?; echo "$rc" >"$deps_rc" ) &
deps_pid=$!
# A process and all it started: to stop the jobs beside the parts when a part fails.
tree() { echo "$1"; for c in $(ps -o pid= --ppid "$1" 2>/dev/null); do tree "$c"; done; }
trap 'for p in $(tree "$deps_pid") ${roots_pid:+$(tree "$roots_pid")} ${arm_build_pid:+$(tree "$arm_build_pid")} ${arm_pid:+$(tree "$arm_pid")} ${vcan_pid:+$(tree "$vcan_pid")}; do kill "$p" 2>/dev/null; done' EXIT
part "install dependencies (beside the lints below; its output after them)"
deps_ok() { while [ ! -s "$deps_rc" ]; do sleep 1; done; [ "$(cat "$deps_rc")" = 0 ]; }
# Once installed: the package tests' throwaway Debian roots (downloads and unpacking, no build
# needed; else the command's tail waited on the network for them), then the arm64 part's
# builds (aarch64 lints, test binaries, the package's binary) in their own target directory
# (scripts/test-arm64.sh), at idle priority: they take only the CPU time the parts below
# leave (their tests wait on real time, the vcan suite's User-mode Linux holds one core), and
# never make those wait. Their output comes after the vcan suite.
roots_log=$(mktemp); roots_rc=$(mktemp)
arm_log=$(mktemp); arm_build_rc=$(mktemp)
(
  deps_ok || { echo 1 >"$roots_rc"; exit 0; }
  rc=0; nice -n 10 scripts/test-package.sh --prepare >"$roots_log" 2>&1 || rc=$?; echo "$rc" >"$roots_rc"
) &
roots_pid=$!
(
  deps_ok || { echo 1 >"$arm_build_rc"; exit 0; }
  rc=0; chrt --idle 0 nice -n 19 scripts/test-arm64.sh --build >"$arm_log" 2>&1 || rc=$?
  echo "$rc" >"$arm_build_rc"
) &
arm_build_pid=$!
part "cargo fmt --check"; cargo fmt --all --check
part "import cycles between modules"; python3 scripts/module_cycles.py
part "cargo clippy"; cargo clippy --workspace --all-targets --features vcan,interop -- -D warnings
# The robot's build (scripts/package-deb.sh's features): code only the lab uses must not linger.
# shellcheck disable=SC2046
cargo clippy $(scripts/package-deb.sh --print-build-args) -- -D warnings
part "install dependencies: done"
deps_ok_rc=0; deps_ok || deps_ok_rc=1
cat "$deps_log"; rm -f "$deps_log"
[ "$deps_ok_rc" = 0 ] || { echo "FAILED: scripts/install-deps.sh (its output above)" >&2; exit 1; }
part "the wire crate without std, for the foot's microcontroller (thumbv7em-none-eabihf)"
cargo build -p presrs-wire --no-default-features --target thumbv7em-none-eabihf
cargo clippy -p presrs-wire --no-default-features --target thumbv7em-none-eabihf -- -D warnings
cargo clippy -p presrs-wire --features alloc --target thumbv7em-none-eabihf -- -D warnings
# With vcan: the vcan suite's binary is built here, with the rest, and its tests listed as
# ignored; tests/vcan/run.sh runs them, on real SocketCAN, beside the test binaries below.
part "cargo test: the build (unit, property, cantools/python-can interop, the vcan suite's)"
cargo test --workspace --features interop,vcan --no-run
part "vcan suite, the host's part: the test build's binaries, the system tests' model"
tests/vcan/run.sh --prepare
# Where this kernel has no CAN the vcan run is User-mode Linux, one CPU, which run.sh pins to
# core 0 (or a VM): it runs beside the test binaries, which take the other core and what
# User-mode Linux leaves of its own (about half: its processes wait on robot time), at nice 5
# so that a User-mode Linux process that wakes gets its core first (the suite's tests judge
# robot time). The arm64 part stays on every core at idle priority: it takes what both leave.
part "vcan suite (its output after cargo test's) beside cargo test's binaries, and at idle priority the rest of scripts/test-arm64.sh (its output last)"
vcan_log=$(mktemp); vcan_rc_file=$(mktemp)
( rc=0; tests/vcan/run.sh --prepared >"$vcan_log" 2>&1 || rc=$?; echo "$rc" >"$vcan_rc_file" ) &
vcan_pid=$!
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
part "cargo test (unit, property, cantools/python-can interop), beside the vcan suite"
# A failure here still shows the vcan suite's and the arm64 part's results below.
test_rc=0; nice -n 5 cargo test --workspace --features interop,vcan || test_rc=$?
part "cargo test done (exit $test_rc); the vcan suite beside it:"
wait "$vcan_pid" || true
vcan_rc=$(cat "$vcan_rc_file" 2>/dev/null); vcan_rc=${vcan_rc:-1}
cat "$vcan_log"; rm -f "$vcan_log" "$vcan_rc_file"
part "vcan suite done (exit $vcan_rc); the arm64 part beside it:"
arm_rc=0; wait "$arm_pid" || arm_rc=$?
cat "$arm_log"; rm -f "$arm_log"
if [ "$test_rc" != 0 ] || [ "$vcan_rc" != 0 ] || [ "$arm_rc" != 0 ]; then
  echo "FAILED: cargo test exit $test_rc, vcan suite exit $vcan_rc, arm64 part exit $arm_rc" >&2
  exit 1
fi
trap - EXIT
part "all tests passed"
