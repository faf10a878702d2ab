#!/usr/bin/env bash
# Every test: format, lints, unit/property/interop tests, and the vcan suite on real SocketCAN
# (inside a VM when this kernel has no CAN). Installs what it needs first.
set -euo pipefail
cd "$(dirname "$0")"
scripts/install-deps.sh
echo "== cargo fmt --check"; cargo fmt --all --check
echo "== cargo clippy"; cargo clippy --workspace --all-targets --features vcan,interop -- -D warnings
echo "== cargo test (unit, property, cantools/python-can interop)"
cargo test --workspace --features interop
echo "== vcan suite"; tests/vcan/run.sh
echo "== all tests passed"
