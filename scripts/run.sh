#!/usr/bin/env bash
# The main job: set up the environment if needed, then reproduce the paper end to end into OUT
# (default out/): demonstrations on train_course with the synthetic driver, training (the paper's
# recipe and ours, several seeds), closed-loop evaluation on test_course and the figure variations,
# and OUT/REPORT.md with Tables 1 and 2, figures and stage timings.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
OUT=${1:-out}
.venv/bin/terrapref reproduce --out "$OUT"
