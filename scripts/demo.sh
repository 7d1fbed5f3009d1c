#!/usr/bin/env bash
# make demo: generate a small scene-1 dataset on the embedded liver phantom with mpirun, check it,
# train the surrogate with cross-validation and print the metrics table. Usage: demo.sh SPY TPY NP
set -euo pipefail
SPY=$1; TPY=$2; NP=${3:-2}
SCENE=data_spec/scenes/demo_scene1.toml
OUT=runs/demo
start=$(date +%s)
echo "== 1/5 generate: mpirun -n $NP fem_sim generate $SCENE --out $OUT/data"
gen_start=$(date +%s)
mpirun -n "$NP" "$SPY" -m fem_sim generate "$SCENE" --out "$OUT/data"
gen_seconds=$(( $(date +%s) - gen_start ))
echo "== 2/5 validate"
"$SPY" -m data_spec validate "$OUT/data"
"$SPY" -m fem_sim summary "$OUT/data"
echo "== 3/5 train: surrogate train --data $OUT/data --run $OUT/train"
"$TPY" -m surrogate train --data "$OUT/data" --run "$OUT/train"
echo "== 4/5 results ($OUT/train: metrics.md, metrics.json, *.png, model/)"
cat "$OUT/train/metrics.md"
echo "== 5/5 look: surrogate.viewer $OUT/train --offscreen (frames + GIF), --compare (FE beside it)"
"$TPY" -m surrogate.viewer "$OUT/train" --offscreen --out "$OUT/frames"
"$TPY" -m surrogate.viewer "$OUT/train" --compare --data "$OUT/data" --offscreen --out "$OUT/frames"
echo "pictures: $OUT/data/summary.png, $OUT/frames/manipulator.gif, $OUT/frames/compare_sim*.png"
echo "the manipulator (a window; under Xvfb on a server): $TPY -m surrogate.viewer $OUT/train"
"$TPY" scripts/demo_report.py --data "$OUT/data" --run "$OUT/train" \
    --generate-seconds "$gen_seconds" --total-seconds "$(( $(date +%s) - start ))"
echo "demo finished in $(( $(date +%s) - start )) s (report: docs/demo.md)"
