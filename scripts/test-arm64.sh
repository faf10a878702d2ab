#!/usr/bin/env bash
# The arm64 checks, run by ./test-all.sh at idle priority: the builds from its start, beside
# the host's builds and tests, the rest beside the vcan suite (their times: CHANGELOG.md):
# 1. clippy for aarch64 on the libraries (the NEON code only compiles there);
# 2. the classifier's unit and integration tests, cross-built for aarch64 and run under
#    qemu-aarch64: correctness only, never timings (qemu emulates the CPU);
# 3. both Debian packages (the amd64 one with the test build's binary); the CLI
#    classification tests (tests/cli_classifier.rs, run by the host) drive the arm64 package's
#    binary under qemu-aarch64; scripts/test-package.sh: the packages install into throwaway
#    Debian roots, and the installed arm64 binary classifies every image of two simulated
#    datasets as the x86-64 one does.
#
#   scripts/test-arm64.sh           all of it (each build is a no-op when already done)
#   scripts/test-arm64.sh --build   only the builds: the lints, the aarch64 test binaries, the
#                                   arm64 package's binary (what needs no host build)
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
# The host's target directory (CARGO_TARGET_DIR, a config's, or ./target), and beside it the
# aarch64 builds' own: cargo locks a target directory's profile directory while it builds (a
# cross build locks the host's release/ too, for its build scripts and proc macros), so in the
# same one ./test-all.sh's aarch64 builds, started at once, would wait on clippy, `cargo test`
# and the amd64 release build, or make them wait.
meta=$(cargo metadata --no-deps --format-version 1)
target_dir=$(python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])' <<<"$meta")
version=$(python3 -c 'import json, sys; print(next(p["version"] for p in json.load(sys.stdin)["packages"] if p["name"] == "presrs"))' <<<"$meta")
cross_dir="$target_dir/cross"
cross() { CARGO_TARGET_DIR="$cross_dir" "$@"; }

scripts/install-deps.sh --cross arm64 --package
triple=aarch64-unknown-linux-gnu
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
# Cargo runs aarch64 test binaries through qemu-user; -L points it at the cross libc.
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="qemu-aarch64 -L /usr/aarch64-linux-gnu"

# The libraries only: the aarch64 code (NEON kernels, the FFT planner) is all in them, and the
# tests and benches, linted on the host, compile for aarch64 in the next step. With
# --all-targets the dev-dependencies (criterion, proptest) were checked for aarch64 too: 77 s
# against 46 s on a fresh target directory (2-core machine, 2026-11-25).
step "cargo clippy --target $triple --lib (node, protocol, wire)"
cross cargo clippy --quiet --target "$triple" -p presrs-node -p presrs-protocol -p presrs-wire --lib -- -D warnings

# --release: the emulated tests run in seconds instead of minutes. The node crate only: the
# CLI's tests cross-built with it compiled the whole workspace and the CLI's dev-dependencies
# in release for aarch64, and the package then compiled much of it again with its own
# features (test build and run 412 s, package 164 s, in CI on a 2-core machine). Apart, on a
# fresh target directory of the same machine: the node crate's test build 151 s (208 s while
# it still had criterion and proptest, which it never used), the package after it 282 s.
# Doctests run on the host only.
# The unit tests (the NEON kernels against the portable ones, the FFT planner) and the
# classifier end to end (training, model files deciding as the build that wrote them). Not the
# service's tests: qemu-user runs the guest's threads on this host's strongly ordered memory,
# so an ordering bug that only ARM's weak memory model shows cannot appear under it, and what
# the service's threads do is tested on the host (its time under qemu for nothing the host does
# not prove; docs/decisions/test-command-time.md).
# Of those, the ones that run code whose aarch64 build differs (the kernels, the planner, the
# model files' arithmetic): the classifier's unit tests and train_classify but its 17-class
# model (class counts are the same code on every CPU). Times: docs/decisions/test-command-time.md.
node_tests=(--quiet --release --target "$triple" -p presrs-node)
if [ "$build_only" = 1 ]; then
  step "node crate tests: the aarch64 build"
  cross cargo test --no-run "${node_tests[@]}" --lib --test train_classify
  step "the arm64 package's binary: cargo build --release --target $triple --bin presrs"
  cross cargo build --release --quiet --target "$triple" --bin presrs
  step "builds done"
  exit 0
fi
step "node crate tests under qemu-aarch64: the classifier's unit tests, train_classify"
cross cargo test "${node_tests[@]}" --lib -- classifier::
cross cargo test "${node_tests[@]}" --test train_classify -- --skip a_model_holds_more_than_sixteen_classes

step "arm64 Debian package"; cross scripts/package-deb.sh --arch arm64
# Beside the amd64 one, where scripts/test-package.sh looks.
mkdir -p "$target_dir/debian" && cp "$cross_dir/debian/presrs_${version}_arm64.deb" "$target_dir/debian/"
# The CLI's classification tests against the binary the arm64 package ships, driven by the
# host's test binary, the one ./test-all.sh's `cargo test` built (scripts/test-exe.sh).
step "CLI classification tests on the arm64 binary under qemu-aarch64"
cli_tests=$(scripts/test-exe.sh cli_classifier)
# The one that trains, evaluates, classifies, repairs and reads bad input; the calibration
# test checks what the host's run of it checks, with the same code (times: the same doc).
PRESRS_TEST_BIN="$cross_dir/$triple/release/presrs" \
  PRESRS_TEST_RUNNER="qemu-aarch64 -L /usr/aarch64-linux-gnu" "$cli_tests" --quiet \
  --exact train_eval_classify_features_repair
# The amd64 package holds the test build's binary (dev profile, the one the CLI and vcan tests
# ran): the packaging is what is tested here, and an x86-64 release build of the workspace
# cost 500 s of the test command (docs/decisions/test-command-time.md); the arm64 package
# above is the release build a robot installs.
host_presrs=$(scripts/test-exe.sh presrs bin)
step "amd64 Debian package (the test build's binary)"
scripts/package-deb.sh --arch amd64 --binary "$host_presrs"
step "both packages in throwaway Debian roots"; scripts/test-package.sh --x86 "$host_presrs"
step "done"
