#!/usr/bin/env bash
# The arm64 checks, run by ./test-all.sh at idle priority: the builds from its start, beside
# the host's builds and tests, the rest beside the vcan suite (their times: CHANGELOG.md):
# 1. clippy for aarch64 on the libraries (the NEON code only compiles there);
# 2. the classifier's unit and integration tests, cross-built for aarch64 and run under
#    qemu-aarch64: correctness only, never timings (qemu emulates the CPU);
# 3. both Debian packages (the arm64 one with the robot's build of presrs, the amd64 one with
#    the test build's binary); scripts/test-package.sh: the packages install into throwaway
#    Debian roots, and the installed arm64 node decides every step of a simulated run's log as
#    the x86-64 one does.
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

# The node crate only: the CLI's tests cross-built with it compiled the whole workspace and the
# CLI's dev-dependencies for aarch64 (test build and run 412 s, package 164 s, in CI on a
# 2-core machine, 2026-11). Doctests run on the host only.
# The test profile (dev: the node and its numeric crates optimised, Cargo.toml), for the tests
# and the package's binary alike, so that they share one build of their dependencies: the
# package's binary built in release took 752 CPU-seconds from scratch, in dev 372
# (docs/decisions/robot-binary.md); the amd64 package holds the host's test build too. A
# robot's package is the release build, `scripts/package-deb.sh --arch arm64`.
node_tests=(--quiet --target "$triple" -p presrs-node)
# What the package ships: the robot's build, without the lab's commands (scripts/package-deb.sh).
robot_build=$(scripts/package-deb.sh --print-build-args)
if [ "$build_only" = 1 ]; then
  step "node crate tests: the aarch64 build"
  cross cargo test --no-run "${node_tests[@]}" --lib --test train_classify
  step "the arm64 package's binary, the robot's build in the test profile: cargo build --target $triple $robot_build"
  cross cargo build --quiet --target "$triple" $robot_build
  step "builds done"
  exit 0
fi
step "node crate tests under qemu-aarch64: the classifier's unit tests, train_classify"
cross cargo test "${node_tests[@]}" --lib -- classifier::
cross cargo test "${node_tests[@]}" --test train_classify -- --skip a_model_holds_more_than_sixteen_classes

step "arm64 Debian package (the robot's build, test profile)"
# A no-op after --build; on its own, the script builds what it packages.
cross cargo build --quiet --target "$triple" $robot_build
cross scripts/package-deb.sh --arch arm64 --binary "$cross_dir/$triple/debug/presrs"
# Beside the amd64 one, where scripts/test-package.sh looks (which runs the installed robot
# build's node on a log beside the x86-64 one: the same decisions).
mkdir -p "$target_dir/debian" && cp "$cross_dir/debian/presrs_${version}_arm64.deb" "$target_dir/debian/"
# The amd64 package holds the test build's binary (dev profile, the one the CLI and vcan tests
# ran): the packaging is what is tested here, and an x86-64 release build of the workspace
# cost 500 s of the test command (docs/decisions/test-command-time.md).
host_presrs=$(scripts/test-exe.sh presrs bin)
step "amd64 Debian package (the test build's binary)"
scripts/package-deb.sh --arch amd64 --binary "$host_presrs"
step "both packages in throwaway Debian roots"; scripts/test-package.sh --x86 "$host_presrs"
step "done"
