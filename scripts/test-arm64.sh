#!/usr/bin/env bash
# The arm64 checks, run by ./test-all.sh (about 6 minutes on a fresh 2-core machine):
# 1. clippy for aarch64 (the NEON code only compiles there);
# 2. the node crate's tests (classifier, stance pipeline) and the CLI classification tests,
#    cross-built for aarch64 and run under qemu-aarch64: correctness only, never timings
#    (qemu emulates the CPU);
# 3. both Debian packages, and scripts/test-package.sh: they install into throwaway Debian
#    roots, and the installed arm64 binary classifies every image of two simulated datasets
#    as the x86-64 one does.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

scripts/install-deps.sh --cross arm64 --package
triple=aarch64-unknown-linux-gnu
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
# Cargo runs aarch64 test binaries through qemu-user; -L points it at the cross libc.
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="qemu-aarch64 -L /usr/aarch64-linux-gnu"

echo "== arm64: cargo clippy --target $triple (node, protocol)"
cargo clippy --quiet --target "$triple" -p presrs-node -p presrs-protocol --all-targets -- -D warnings

# --release: the same build serves the tests, the CLI test's binary and the package, and the
# emulated tests run in seconds instead of minutes.
echo "== arm64: node crate tests under qemu-aarch64"
cargo test --quiet --release --target "$triple" -p presrs-node
echo "== arm64: CLI classification tests under qemu-aarch64"
PRESRS_TEST_RUNNER="qemu-aarch64 -L /usr/aarch64-linux-gnu" \
  cargo test --quiet --release --target "$triple" --test cli_classifier

echo "== arm64 and amd64 Debian packages"
scripts/package-deb.sh --arch arm64
scripts/package-deb.sh --arch amd64
scripts/test-package.sh
