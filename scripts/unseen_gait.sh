#!/usr/bin/env bash
# A gait the model never saw, with the CLI only: per seed, models trained on two of the
# paper's gaits (sensor 1), calibrated on another run of them (sensor 2), judged on a fresh
# sensor (3) on their own gaits and on the third gait. Prints `presrs eval --json`'s share of
# known stances called unknown and classified right. What a lab that adds a gait after
# training meets; tests/open_set.rs asserts one seed of it.
#
#   scripts/unseen_gait.sh [SEED ...]     (default: 1 2 3; PRESRS=path/to/presrs)
set -euo pipefail
presrs=${PRESRS:-presrs}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# merge OUT SRC...: one folder per terrain, each source's images named after it (interleaved
# by number, so that a calibration capped at its first images per terrain sees every gait).
merge() {
  local out=$1 src g t f n
  shift
  for src in "$@"; do
    g=$(basename "$src")
    for t in "$src"/*/; do
      t=$(basename "$t")
      mkdir -p "$out/$t"
      for f in "$src/$t"/*.pgm; do
        n=$(basename "$f" .pgm)
        cp "$f" "$out/$t/$n-$g.pgm"
      done
    done
  done
}

eval_line() { # MODEL DIR LABEL
  "$presrs" eval --model "$1" --data "$2" --json | python3 -c "
import json, sys
d = json.load(sys.stdin)
print('%s: %d stances, unknown %.1f%%, right %.1f%%' % (sys.argv[1], d['n_tested'],
      100 * d['unknown_rate'], 100 * d['overall_accuracy']))
" "$3"
}

for seed in "${@:-1 2 3}"; do
  for s in $seed; do
    w=$work/seed$s
    mkdir -p "$w"
    for g in 1 2 3; do
      for sensor in 1 2 3; do
        "$presrs" lab dataset dynamic --n 60 --gait "G$g" --sensor "$sensor" \
          --seed $((s * 100 + sensor * 10 + g)) --out "$w/G$g-s$sensor" > /dev/null
      done
    done
    for pair in 13 12 23; do
      a=${pair:0:1}; b=${pair:1:1}; m=$w/G$pair
      for sensor in 1 2 3; do merge "$m-s$sensor" "$w/G$a-s$sensor" "$w/G$b-s$sensor"; done
      "$presrs" train --data "$m-s1" --calibrate "$m-s2" --out "$m.json" --crop 0,3,6,0 \
        --normalize-load --per-class 60 --train 40 --seed "$s" > /dev/null
      unseen=$((6 - a - b))
      eval_line "$m.json" "$m-s3" "seed $s, trained on G$a+G$b, their fresh run"
      eval_line "$m.json" "$w/G$unseen-s3" "seed $s, trained on G$a+G$b, unseen G$unseen"
    done
  done
done
