#!/bin/bash
# How many stances per terrain `train` draws (--per-class), measured on the next session:
# docs/decisions/train-draw.md. Usage: scripts/train_draw.sh [WORKDIR] (from the repository's
# root, after `cargo build --release`; about 15 min on 2 cores). The SpeedPP2D part needs
# `pip install jiku-data`.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
P=$ROOT/target/release/presrs
W=${1:-/tmp/train-draw}
mkdir -p "$W"
cd "$W"
# The simulator: sessions a and a+1 train (the second calibrates), a+3 is the next session
# of known ground, the sand track with seed a+2 new ground.
for a in 1 11 21 31 41; do
  b=$((a + 1)); n=$((a + 3)); s=$((a + 2)); d=pair$a
  mkdir -p $d && cd $d
  for x in $a $b $n; do
    $P demo --steps 300 --seed $x --candump r$x.log --truth r$x.csv > /dev/null 2>&1
  done
  $P demo --track "$ROOT/examples/sand-track.toml" --seed $s --candump sand.log --truth sand.csv > /dev/null 2>&1
  rm -rf set
  for x in $a $b; do $P capture --replay r$x.log --labels r$x.csv --out set > /dev/null 2>&1; done
  for pc in 20 30 40 60; do
    $P train --data set --out m$pc.json --per-class $pc > train$pc.txt 2>&1
    h=$(grep -o "h = [0-9]*" train$pc.txt)
    k=$($P node --replay r$n.log --model m$pc.json --truth r$n.csv 2>&1 > /dev/null | grep -o "known ground called unknown.*")
    f=$($P node --replay sand.log --model m$pc.json --truth sand.csv 2>&1 > /dev/null | grep -o "new ground found: .*")
    echo "sim pair $a --per-class $pc ($h): next session $k; sand $f"
  done
  rm -f ./*.log
  cd ..
done
# SpeedPP2D (real plantar pressure, one terrain per person): 36 trials per person train, 12
# calibrate, 12 are the next session, in two layouts of the trials.
python3 "$ROOT/scripts/speedpp2d.py" --out pp2d > /dev/null
for layout in first last; do
  rm -rf pp-$layout pp-$layout-fresh
  python3 - "$layout" << 'PY'
import csv, os, re, sys
layout = sys.argv[1]
rows = list(csv.DictReader(open("pp2d/manifest.csv")))
header = list(rows[0].keys())
def role(t):
    if layout == "first":
        return "sessionA" if t <= 11 else "sessionB" if t <= 15 else "fresh"
    return "sessionA" if t >= 8 else "sessionB" if t >= 4 else "fresh"
out = {}
for r in rows:
    r["source"] = role(int(re.search(r"trial(\d+)", r["file"]).group(1)))
    d = f"pp-{layout}-fresh" if r["source"] == "fresh" else f"pp-{layout}"
    os.makedirs(os.path.join(d, os.path.dirname(r["file"])), exist_ok=True)
    os.symlink(os.path.abspath(os.path.join("pp2d", r["file"])), os.path.join(d, r["file"]))
    out.setdefault(d, []).append(r)
for d, rs in out.items():
    with open(os.path.join(d, "manifest.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=header)
        w.writeheader()
        w.writerows(rs)
PY
  for pc in 20 24; do
    $P train --data pp-$layout --out pp-$layout-$pc.json --terrains pp2d/terrains.toml --per-class $pc > /dev/null 2>&1
    e=$($P eval --model pp-$layout-$pc.json --data pp-$layout-fresh --terrains pp2d/terrains.toml 2>&1 | grep -E "overall|called unknown" | tr '\n' ' ')
    echo "SpeedPP2D trials $layout --per-class $pc: next session $e"
  done
done
