#!/usr/bin/env bash
# The main job: set up the environment if needed, then run terrapref's end-to-end job into out/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
OUT=${1:-out}
.venv/bin/terrapref show demo_course --out "$OUT/demo_course_map.png"
.venv/bin/terrapref render demo_course --pose 8 10 0 --out "$OUT/demo_course_seg.png" --preview "$OUT/demo_course_view.png"
