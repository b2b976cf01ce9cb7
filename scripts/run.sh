#!/usr/bin/env bash
# The main job: set up the environment if needed, then reproduce the paper end to end into OUT
# (default out/): demonstrations with the synthetic driver (train_course for the paper's recipe and
# ours, teach_course for the default recipe teach), training (several seeds), closed-loop evaluation
# on test_course and the figure variations, and OUT/REPORT.md with Tables 1 and 2, agreement with the
# driver, 95% intervals, figures and stage timings.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
OUT=${1:-out}
.venv/bin/terrapref reproduce --out "$OUT" --force   # a run before it is replaced whole, once this one is complete
