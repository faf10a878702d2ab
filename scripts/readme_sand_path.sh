#!/usr/bin/env bash
# The README's path with the controller running, then sand the model never saw:
#   two closed-loop recordings (`presrs demo --candump --truth`, seeds A and B, 400 steps),
#   `capture --labels`, `train` with its defaults; then the sand track (seeds 3 and 4) with that
#   model. Prints, per sand run, the sand steps and the known steps called unknown.
#
#   scripts/readme_sand_path.sh A B [WORKDIR]     (PRESRS: the binary; default target/release/presrs)
#
# docs/decisions/unknown-energy-train.md and unknown-one-session.md quote it.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
P=${PRESRS:-$root/target/release/presrs}
a=$1; b=$2; w=${3:-$(mktemp -d)}
mkdir -p "$w"; cd "$w"; rm -rf set
for s in "$a" "$b"; do
  "$P" demo --steps 400 --seed "$s" --candump "r$s.log" --truth "r$s.csv" >/dev/null 2>&1
  "$P" capture --replay "r$s.log" --labels "r$s.csv" --out set >/dev/null
done
"$P" train --data set --out m.json >train.txt
for s in 3 4; do
  "$P" demo --track "$root/examples/sand-track.toml" --steps 300 --seed "$s" --model m.json \
    --csv "sand$s.csv" >/dev/null 2>&1
  python3 - "sand$s.csv" "$a" "$b" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
sand = [r for r in rows if r["true_terrain"] == "sand"]
known = [r for r in rows if r["true_terrain"] != "sand"]
u = lambda rs: sum(r["classified"] == "unknown" for r in rs)
pct = lambda n, d: 100.0 * n / max(1, d)
print(f"trained on seeds {sys.argv[2]},{sys.argv[3]}; {sys.argv[1]}: sand unknown {u(sand)}/{len(sand)} "
      f"= {pct(u(sand), len(sand)):.1f}%; known unknown {u(known)}/{len(known)} = {pct(u(known), len(known)):.1f}%")
PY
done
echo "work dir: $w (train's report: $w/train.txt)"
