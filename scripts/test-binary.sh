#!/usr/bin/env bash
# Prints the path of one integration test's executable, building it if needed, with the
# features ./test-all.sh's `cargo test` uses:
#
#   scripts/test-binary.sh cli_classifier      # the host's test driver (scripts/test-arm64.sh)
#   scripts/test-binary.sh vcan                # the vcan suite (tests/vcan/run.sh)
#
# Always with --workspace --tests: cargo activates a package's dev-dependencies (and so their
# features) only when it builds one of that package's test targets, and a build of one target
# (`--test cli_classifier` alone) unified the dependencies' features differently from the full
# run and recompiled a share of the workspace (82 s in CI, 2026-11-26). With the same targets
# as the full run, only the named one compiles, if it was not built yet (tests/vcan.rs is
# `test = false`: plain `cargo test` leaves it to tests/vcan/run.sh).
set -euo pipefail
name=${1:?usage: scripts/test-binary.sh TEST_NAME}
cd "$(dirname "$0")/.."
cargo test --quiet --workspace --features interop,vcan --tests --test "$name" --no-run \
  --message-format=json-render-diagnostics | python3 -c '
import json, sys
name = sys.argv[1]
exe = [m["executable"] for m in map(json.loads, sys.stdin)
       if m.get("reason") == "compiler-artifact" and m["target"]["name"] == name
       and m.get("executable")]
if not exe:
    sys.exit(f"test-binary: cargo built no test executable named {name}")
print(exe[-1])' "$name"
