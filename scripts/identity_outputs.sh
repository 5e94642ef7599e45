#!/bin/bash
# Writes the outputs that must stay byte-identical when code moves (issue 26): the paper's tables
# (`reproduce`, 6 scenes, 2 folds, 1 epoch) and fly passes (fast/slow presets, every --predict mode,
# the truth and a trained model), with a fixed compute budget so no wall-clock time enters a pass.
#
# usage: scripts/identity_outputs.sh SRC OUT     (SRC: a checkout; its src/ is put first on PYTHONPATH)
#   git worktree add /tmp/before <commit>
#   scripts/identity_outputs.sh /tmp/before /tmp/out-before
#   scripts/identity_outputs.sh . /tmp/out-now
#   python scripts/compare_outputs.py /tmp/out-before /tmp/out-now
set -euo pipefail
SRC=$1; OUT=$2
SRC=$(cd "$SRC" && pwd)
export PYTHONPATH=$SRC/src
rm -rf $OUT; mkdir -p $OUT
cd $OUT
dyntarget synth --scenes 6 --size 128 --seed 0 --out scenes --quiet
dyntarget reproduce --data scenes --out repro --folds 2 --epochs 1 --quiet > repro.log 2>&1
dyntarget synth --strip --scenes 1 --size 256 --plumes 4 --seed 0 --out strips --quiet
dyntarget synth --scenes 2 --size 256 --seed 1 --out flyscenes --quiet
dyntarget train --data flyscenes --classifier logistic-regression --out model > train.log 2>&1
for preset in fast slow; do
  for pred in none wind two-looks; do
    dyntarget fly --scene strips/strip-0000.tif --truth --planner lawnmower-transect --agility $preset --predict $pred --compute-budget-s 0.05 --out fly-truth-$preset-$pred > /dev/null 2>&1 || echo "fly truth $preset $pred rc=$?"
  done
  dyntarget fly --scene strips/strip-0000.tif --model model --planner track-center --agility $preset --compute-budget-s 0.05 --out fly-lr-$preset > /dev/null 2>&1 || echo "fly lr $preset rc=$?"
done
rm -rf repro/models model
