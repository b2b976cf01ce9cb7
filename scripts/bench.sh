#!/usr/bin/env bash
# Run the benchmarks on one core: render time per frame, simulation-loop frame rate,
# utility features per frame, recording train_course with the synthetic driver, and the
# default decision on relief beside the flat one (two models made first, about 3 minutes).
# Extra arguments go to benchmarks/bench_sim.py (e.g. --poses 2000 --frames 3000).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# One core and single-threaded numeric libraries, so the numbers mean "per core".
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMEXPR_NUM_THREADS=1 VECLIB_MAXIMUM_THREADS=1
pin=()
if command -v taskset >/dev/null 2>&1; then
  pin=(taskset -c 0)
fi
${pin[@]+"${pin[@]}"} .venv/bin/python benchmarks/bench_sim.py "$@"
${pin[@]+"${pin[@]}"} .venv/bin/python benchmarks/bench_demos.py
# The default decision on relief beside the flat one, in turn: a model of one drive of
# teach_relief (the shaky driver, the default relief style) and one of teach_course, made afresh.
models=$(mktemp -d)
trap 'rm -rf "$models"' EXIT
for course in teach_relief teach_course; do
  style=(--style shaky --relief-style default)
  [ "$course" = teach_course ] && style=()
  .venv/bin/terrapref record "$course" ${style[@]+"${style[@]}"} --out "$models/$course" --quiet
  .venv/bin/terrapref train "$models/$course" --out "$models/$course.safetensors" >/dev/null
done
${pin[@]+"${pin[@]}"} .venv/bin/python benchmarks/bench_model.py "$models/teach_relief.safetensors" genrelief:2000 \
  --beside "$models/teach_course.safetensors" gen:2000
