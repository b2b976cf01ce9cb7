#!/usr/bin/env bash
# The main job: set up the environment if needed, then run terrapref end to end into OUT (default out/):
# draw the packaged courses, record a demonstration on train_course with the synthetic driver,
# inspect it (zone choices against expectations, driven-path figure) and featurise it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
OUT=${1:-out}
T=.venv/bin/terrapref
mkdir -p "$OUT"
for course in train_course test_course; do
  "$T" show "$course" --out "$OUT/$course.png"
done
"$T" render train_course --pose 16 10 0 --out "$OUT/train_course_seg.png" --preview "$OUT/train_course_view.png"
"$T" record train_course --driver expert --seed 0 --out "$OUT/demo_seed0" --force
"$T" inspect "$OUT/demo_seed0"
"$T" featurize "$OUT/demo_seed0" --out "$OUT/demo_seed0.safetensors"
echo "main job done: figures, recording and dataset in $OUT/"
