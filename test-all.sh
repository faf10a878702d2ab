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
part "install dependencies"; scripts/install-deps.sh
part "cargo fmt --check"; cargo fmt --all --check
part "cargo clippy"; cargo clippy --workspace --all-targets --features vcan,interop -- -D warnings
part "protocol without std, for the foot's microcontroller (thumbv7em-none-eabihf)"
cargo build -p presrs-protocol --no-default-features --target thumbv7em-none-eabihf
cargo clippy -p presrs-protocol --no-default-features --target thumbv7em-none-eabihf -- -D warnings
part "cargo test (unit, property, cantools/python-can interop)"
cargo test --workspace --features interop
part "arm64: cross-build, tests under qemu-aarch64, Debian packages"; scripts/test-arm64.sh
part "vcan suite"; tests/vcan/run.sh
part "all tests passed"
