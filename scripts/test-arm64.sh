#!/usr/bin/env bash
# The arm64 checks, run by ./test-all.sh beside the vcan suite, at idle priority on the cores it
# leaves (their times: CHANGELOG.md):
# 1. clippy for aarch64 on the libraries (the NEON code only compiles there);
# 2. the node crate's unit and integration tests (classifier, stance pipeline), cross-built
#    for aarch64 and run under qemu-aarch64: correctness only, never timings (qemu emulates
#    the CPU);
# 3. both Debian packages; the CLI classification tests (tests/cli_classifier.rs, run by the
#    host) drive the arm64 package's binary under qemu-aarch64; scripts/test-package.sh: the
#    packages install into throwaway Debian roots, and the installed arm64 binary classifies
#    every image of two simulated datasets as the x86-64 one does.
#
#   scripts/test-arm64.sh           all of it (each build is a no-op when already done)
#   scripts/test-arm64.sh --build   only the builds: the lints, the aarch64 test binaries, the
#                                   arm64 package's binary; ./test-all.sh runs them at idle
#                                   priority beside the vcan suite, and the rest after it
set -euo pipefail
build_only=0
case "${1:-}" in
  "") ;;
  --build) build_only=1 ;;
  *) echo "test-arm64: unknown argument \`$1\` (use --build, or none)" >&2; exit 2 ;;
esac
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

# --release: the emulated tests run in seconds instead of minutes. The node crate only: the
# CLI's tests cross-built with it compiled the whole workspace and the CLI's dev-dependencies
# in release for aarch64, and the package then compiled much of it again with its own
# features (test build and run 412 s, package 164 s, in CI on a 2-core machine). Apart, on a
# fresh target directory of the same machine: the node crate's test build 151 s (208 s while
# it still had criterion and proptest, which it never used), the package after it 282 s.
# Doctests run on the host only.
node_tests=(--quiet --release --target "$triple" -p presrs-node --lib --test service --test train_classify)
if [ "$build_only" = 1 ]; then
  step "node crate tests: the aarch64 build"
  cargo test --no-run "${node_tests[@]}"
  step "the arm64 package's binary: cargo build --release --target $triple --bin presrs"
  cargo build --release --quiet --target "$triple" --bin presrs
  step "builds done"
  exit 0
fi
step "node crate tests under qemu-aarch64"
cargo test "${node_tests[@]}"

step "arm64 Debian package"; scripts/package-deb.sh --arch arm64
# The CLI's classification tests against the binary the arm64 package ships, driven by the
# host's test binary, the one ./test-all.sh's `cargo test` built (scripts/test-exe.sh).
step "CLI classification tests on the arm64 binary under qemu-aarch64"
target_dir=$(cargo metadata --no-deps --format-version 1 |
  python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
cli_tests=$(scripts/test-exe.sh cli_classifier)
PRESRS_TEST_BIN="$target_dir/$triple/release/presrs" \
  PRESRS_TEST_RUNNER="qemu-aarch64 -L /usr/aarch64-linux-gnu" "$cli_tests" --quiet
step "amd64 Debian package"; scripts/package-deb.sh --arch amd64
step "both packages in throwaway Debian roots"; scripts/test-package.sh
step "done"
