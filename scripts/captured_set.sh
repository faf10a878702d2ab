#!/usr/bin/env bash
# A training set captured as a lab captures its robot's: the four hopping terrains with sand
# among them (wood, sand, clay, grass), one 15 s run per terrain on each of sensors 1-3 (the
# simulator on a one-terrain track holding G2, written as a candump log), each log through
# `presrs capture --labels`, so the manifest names three runs per terrain. For
# `presrs lab experiment open-set --data OUT --crop 0,3,6,0 --normalize-load`: the left-out sand
# that texture cannot find, and what a check costs on images that came over the bus
# (docs/real-robot.md, "The texture check").
#
#   scripts/captured_set.sh OUT     (PRESRS=path/to/presrs; about a minute)
set -euo pipefail
presrs=${PRESRS:-presrs}
out=${1:?usage: scripts/captured_set.sh OUT}
if [ -e "$out" ]; then
  echo "$out exists: give a new folder (capture appends to a set)" >&2
  exit 2
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for t in wood sand clay grass; do
  printf 'diameter_m = 2.8\n\n[[segments]]\nterrain = "%s"\nlength_m = 8.8\n' "$t" >"$work/$t.toml"
  for s in 1 2 3; do
    log="$work/${t}_run$s.log"
    "$presrs" lab sim --log "$log" --truth "$work/${t}_run$s.csv" --track "$work/$t.toml" \
      --duration 15 --sensor "$s" --seed $((40 + s)) >/dev/null
    "$presrs" capture --replay "$log" --labels "$work/${t}_run$s.csv" --out "$out" >/dev/null
  done
done
echo "wrote $out: $(($(wc -l <"$out/manifest.csv") - 1)) stances"
