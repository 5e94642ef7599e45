#!/bin/bash
# Writes the outputs that must stay byte-identical when code moves (issues 26 and 39): the paper's
# tables (`reproduce`, 6 scenes, 2 folds, 1 epoch), 17 fly passes (fast/slow presets, every --predict
# mode, the truth and a trained model, GEO cueing, a 3D strip under each --parallax mode), `evaluate
# dynamic` on small moving scenes (`synth --frames`) and `plan` with a previous look, an agility
# preset and the HTML view, with a fixed compute budget so no wall-clock time enters a pass. A few
# minutes with nice on 2 cores.
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
# moving worlds are 3D by default since --flat exists: the strip of the passes below is flat (a
# 3D strip is flown further down)
FLAT=; [[ $(dyntarget synth --help) == *--flat* ]] && FLAT=--flat
dyntarget synth --scenes 6 --size 128 --seed 0 --out scenes --quiet
dyntarget reproduce --data scenes --out repro --folds 2 --epochs 1 --quiet > repro.log 2>&1
dyntarget synth --strip --scenes 1 --size 256 --plumes 4 --seed 0 $FLAT --out strips --quiet
dyntarget synth --scenes 2 --size 256 --seed 1 --out flyscenes --quiet
dyntarget train --data flyscenes --classifier logistic-regression --out model > train.log 2>&1
STRIP=strips/strip-0000.tif
fly() {  # fly NAME ARGS...: one pass with a fixed compute budget, its rc reported when non-zero
  local name=$1; shift
  dyntarget fly --scene $STRIP "$@" --compute-budget-s 0.05 --out fly-$name > fly-$name.log 2>&1 || echo "fly $name rc=$?"
}
for preset in fast slow; do
  for pred in none wind two-looks; do
    fly truth-$preset-$pred --truth --planner lawnmower-transect --agility $preset --predict $pred
  done
  fly lr-$preset --model model --planner track-center --agility $preset
done
fly lr-fast-two-looks --model model --planner lawnmower-transect --agility fast --predict two-looks
fly lr-slow-wind --model model --planner track-center --agility slow --predict wind --wind-mps 6 --wind-from-deg 120
fly geo-truth-two-looks --truth --geo --planner lawnmower-transect --agility fast --predict two-looks
fly geo-lr-slow --model model --geo --planner track-center --agility slow --predict two-looks
fly geo-truth-omniscient --truth --geo-omniscient --planner lawnmower-transect --agility slow
# 3D strip (plumes with heights, oblique look-ahead): parallax estimated, true and prior, and a model
dyntarget synth --strip --scenes 1 --size 256 --plumes 3 --seed 3 --out strips3d --quiet
STRIP=strips3d/strip-0003.tif  # a strip is named by its seed
fly 3d-truth-estimated --truth --planner lawnmower-transect --agility fast --parallax estimated
fly 3d-truth-true --truth --planner lawnmower-transect --agility fast --parallax true
fly 3d-truth-prior --truth --planner lawnmower-transect --agility fast --plume-height-km 8 --parallax prior
fly 3d-lr-estimated --model model --planner track-center --agility slow --parallax estimated
# moving scenes: evaluate dynamic (static, predictive, wind-prior under an agility preset) and plan
dyntarget synth --scenes 3 --size 64 --frames 3 --seed 2 $FLAT --out seqs --quiet
dyntarget evaluate dynamic --data seqs --out dynamic --folds 2 --epochs 1 --classifiers logistic-regression --modes static,predictive,wind-prior --latencies 0,30 --agility fast --planners lawnmower-transect,track-center --quiet > dynamic.log 2>&1 || echo "evaluate dynamic rc=$?"
S=seqs/dyn-0002-0000
dyntarget plan $S/f002.tif --mask $S/f002_mask.tif --previous $S/f001.tif --previous-mask $S/f001_mask.tif --interval-s 10 --lead-s 30 --planner lawnmower-transect --agility fast --html plan-masks.html --out plan-masks.geojson > plan-masks.log 2>&1 || echo "plan masks rc=$?"
dyntarget plan $S/f002.tif --model model --force --previous $S/f001.tif --interval-s 10 --lead-s 30 --planner utility-max --agility slow --html plan-model.html --out plan-model.csv > plan-model.log 2>&1 || echo "plan model rc=$?"
dyntarget plan $S/f002.tif --mask $S/f002_mask.tif --wind-mps 8 --wind-from-deg 270 --lead-s 60 --planner track-center --agility fast --html plan-wind.html --out plan-wind.geojson > plan-wind.log 2>&1 || echo "plan wind rc=$?"
rm -rf repro/models model
