#!/usr/bin/env bash
# Run the benchmarks on one core: render time per frame, simulation-loop frame rate,
# utility features per frame, and recording train_course with the synthetic driver.
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
"${pin[@]}" .venv/bin/python benchmarks/bench_sim.py "$@"
"${pin[@]}" .venv/bin/python benchmarks/bench_demos.py
