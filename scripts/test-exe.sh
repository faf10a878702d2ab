#!/usr/bin/env bash
# Prints the path of one executable of ./test-all.sh's `cargo test` build:
#
#   scripts/test-exe.sh NAME            an integration test target (vcan, cli_classifier, ...)
#   scripts/test-exe.sh presrs bin      the binary the CLI tests run (dev profile)
#   scripts/test-exe.sh NAME example    an example `cargo test` built to check it compiles
#
# It asks cargo for that same selection (--workspace --features interop,vcan), so after the
# test command's `cargo test` nothing is rebuilt: one target alone (`--test NAME`) unifies the
# dependencies' features differently and recompiled part of the workspace (82-84 s, clean-clone
# runs of 2026-11-26).
set -euo pipefail
name=${1:?usage: scripts/test-exe.sh TARGET_NAME [test|bin|example]}
kind=${2:-test}
case "$kind" in test|bin|example) ;; *) echo "test-exe: unknown kind \`$kind\` (use test, bin or example)" >&2; exit 2 ;; esac
cd "$(dirname "$0")/.."
exe=$(cargo test --workspace --features interop,vcan --no-run --message-format=json 2>/dev/null |
  python3 -c 'import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if (m.get("reason") == "compiler-artifact" and m["target"]["name"] == sys.argv[1]
            and sys.argv[2] in m["target"]["kind"] and m.get("executable")
            and m["profile"]["test"] == (sys.argv[2] == "test")):
        print(m["executable"])' "$name" "$kind" | tail -1)
[ -n "$exe" ] || { echo "test-exe: cargo built no $kind executable named \`$name\`" >&2; exit 1; }
echo "$exe"
