#!/usr/bin/env bash
# Prints the path of one test executable of ./test-all.sh's `cargo test` build:
#
#   scripts/test-exe.sh NAME        (NAME: an integration test target, e.g. vcan, cli_classifier)
#
# It asks cargo for that same selection (--workspace --features interop,vcan), so after the
# test command's `cargo test` nothing is rebuilt: one target alone (`--test NAME`) unifies the
# dependencies' features differently and recompiled part of the workspace (82-84 s, clean-clone
# runs of 2026-11-26).
set -euo pipefail
name=${1:?usage: scripts/test-exe.sh TEST_TARGET_NAME}
cd "$(dirname "$0")/.."
exe=$(cargo test --workspace --features interop,vcan --no-run --message-format=json 2>/dev/null |
  python3 -c 'import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == sys.argv[1] and m.get("executable"):
        print(m["executable"])' "$name" | tail -1)
[ -n "$exe" ] || { echo "test-exe: cargo built no test executable named \`$name\`" >&2; exit 1; }
echo "$exe"
