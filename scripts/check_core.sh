#!/usr/bin/env bash
# Check that `pip install terrapref` (the core, no extras) installs lean and works: in a fresh
# virtual environment in a temporary folder, install the package without extras (pinned by
# requirements.lock), check that no extra's package (nor CUDA) came with it, then record a short
# drive, train a model, evaluate it on a generated layout and run the other quick commands; and
# check that each command of an extra refuses in one line naming it, with exit code 2. Prints
# the environment's size. With --full, also builds the environment with every extra (PyTorch
# first from its CPU build, as scripts/setup.sh does) and prints its size.
#
#   bash scripts/check_core.sh [--full]
set -euo pipefail
unset PYTHONPATH  # the installed package runs, not a source tree
cd "$(dirname "$0")/.."
repo=$(pwd)
PY=${PYTHON:-python3}
full=0
[ "${1:-}" = "--full" ] && full=1
work=$(mktemp -d "${TMPDIR:-/tmp}/terrapref-core.XXXXXX")
trap 'rm -rf "$work"' EXIT
PIP=(--quiet --disable-pip-version-check)

# The package from a copy of the tree, so that the build leaves nothing here.
mkdir "$work/tree"
tar --exclude=__pycache__ --exclude='*.egg-info' -cf - pyproject.toml README.md src | tar -xf - -C "$work/tree"

echo "core: installing into a fresh environment ..."
"$PY" -m venv "$work/core"
"$work/core/bin/python" -m pip install "${PIP[@]}" -c "$repo/requirements.lock" "$work/tree"
extras=$("$work/core/bin/python" -m pip list --format=freeze --disable-pip-version-check \
         | grep -iE '^(torch|pygame|ray|rosbags|onnx|onnxruntime|foxglove-sdk|nvidia-[^=]*)==' || true)
if [ -n "$extras" ]; then
  echo "FAIL: the core installed extras' packages:"; echo "$extras"; exit 1
fi

T="$work/core/bin/terrapref"
cd "$work"  # away from the tree: the installed package runs
echo "core: record, train, evaluate (the first run compiles the numerical loops) ..."
"$T" validate teach_course
"$T" render teach_course --out view.png
"$T" show teach_course --out map.png
"$T" record fig7_rock_vs_non_traversable_left --disturb 0 --out rec --quiet
"$T" inspect rec --out rec.png --no-preference >/dev/null
"$T" train rec --out model.safetensors --epochs 20 --members 1 | tail -n 1
"$T" info model.safetensors >/dev/null
"$T" evaluate model.safetensors gen:7 --seeds 1 --no-driver --out eval | tail -n 1
"$T" route fig7_rock_vs_non_traversable_left --model model.safetensors --out route.yaml | tail -n 1

# A CNN model file: loading it reaches the CNN baseline, which needs the cnn extra.
"$work/core/bin/python" -c "
import numpy as np
from terrapref.learning.model_file import FORMAT
from terrapref.tensorfile import write_tensor_file
write_tensor_file('cnn.safetensors', {'w': np.zeros(1, np.float32)}, {'format': FORMAT, 'kind': 'cnn'})"

refuses() {  # refuses EXTRA ARGS...: `terrapref ARGS` exits with code 2 and one line naming EXTRA
  local extra=$1 rc=0
  shift
  "$T" "$@" >out.txt 2>err.txt || rc=$?
  if [ "$rc" -ne 2 ] || [ "$(wc -l <err.txt)" -ne 1 ] || ! grep -q "pip install 'terrapref\[$extra\]'" err.txt; then
    echo "FAIL: terrapref $* (exit code $rc):"; cat out.txt err.txt; exit 1
  fi
  echo "  terrapref $*  ->  $(cat err.txt)"
}
echo "core: the extras' commands say which extra to install:"
refuses teleop drive teach_course
refuses robot export model.safetensors --format onnx --out model.onnx
refuses robot export rec --format mcap --out rec.mcap
refuses robot evaluate model.safetensors gen:7 --seeds 1 --mcap --out eval_mcap
refuses robot evaluate model.safetensors gen:7 --seeds 1 --live --live-port 0 --out eval_live
refuses ray evaluate model.safetensors gen:7 --seeds 1 --engine ray --out eval_ray
refuses cnn evaluate cnn.safetensors gen:7 --seeds 1 --out eval_cnn
refuses cnn study --quick --out study

echo "core environment: $(du -sh "$work/core" | cut -f1)"
if [ "$full" = 1 ]; then
  echo "full: installing every extra into a fresh environment ..."
  "$PY" -m venv "$work/full"
  "$work/full/bin/python" -m pip install "${PIP[@]}" "torch==2.13.0"
  "$work/full/bin/python" -m pip install "${PIP[@]}" -c "$repo/requirements.lock" "$work/tree[all]"
  if "$work/full/bin/python" -m pip list --format=freeze --disable-pip-version-check | grep -iq '^nvidia-'; then
    echo "FAIL: the full environment installed CUDA packages"; exit 1
  fi
  "$work/full/bin/python" -c "import pygame, rosbags, onnx, onnxruntime, foxglove, ray, torch"
  echo "full environment (every extra, no test tools): $(du -sh "$work/full" | cut -f1)"
fi
echo "ok: the core works without its extras"
