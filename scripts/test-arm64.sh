#!/usr/bin/env bash
# The arm64 checks, run by ./test-all.sh (about 9 minutes on a fresh 2-core machine):
# 1. clippy for aarch64 on the libraries (the NEON code only compiles there);
# 2. the node crate's unit and integration tests (classifier, stance pipeline) and the CLI
#    classification tests, cross-built for aarch64 and run under qemu-aarch64: correctness
#    only, never timings (qemu emulates the CPU);
# 3. both Debian packages, and scripts/test-package.sh: they install into throwaway Debian
#    roots, and the installed arm64 binary classifies every image of two simulated datasets
#    as the x86-64 one does.
set -euo pipefail
t0=$SECONDS
# Each step says when it started: the part is the test command's second longest.
step() { echo "== arm64: $1 (at $((SECONDS - t0)) s)"; }
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

scripts/install-deps.sh --cross arm64 --package
triple=aarch64-unknown-linux-gnu
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
# Cargo runs aarch64 test binaries through qemu-user; -L points it at the cross libc.
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="qemu-aarch64 -L /usr/aarch64-linux-gnu"

# The libraries only: the aarch64 code (NEON kernels, the FFT planner) is all in them, and the
# tests and benches, linted on the host, compile for aarch64 in the next step. With
# --all-targets the dev-dependencies (criterion, proptest) were checked for aarch64 too: 77 s
# against 46 s on a fresh target directory (2-core machine, 2026-11-25).
step "cargo clippy --target $triple --lib (node, protocol)"
cargo clippy --quiet --target "$triple" -p presrs-node -p presrs-protocol --lib -- -D warnings

# --release: the emulated tests run in seconds instead of minutes. One cargo invocation for the
# node crate's tests and the CLI's: built apart, each with its own feature set (dev-dependencies
# unify differently per package), the workspace compiled twice: 126 s + 170 s apart, 228 s
# together on a fresh 2-core machine (2026-11-24). Doctests run on the host only.
step "node crate and CLI classification tests under qemu-aarch64"
PRESRS_TEST_RUNNER="qemu-aarch64 -L /usr/aarch64-linux-gnu" \
  cargo test --quiet --release --target "$triple" -p presrs-node -p presrs \
  --lib --test service --test train_classify --test cli_classifier

step "arm64 Debian package"; scripts/package-deb.sh --arch arm64
step "amd64 Debian package"; scripts/package-deb.sh --arch amd64
step "both packages in throwaway Debian roots"; scripts/test-package.sh
step "done"
