#!/usr/bin/env bash
# Create (or refresh) the project's virtual environment in .venv with pinned dependencies: the
# core, every extra (all: teleop, robot, ray, cnn) and the test tools.
# PyTorch is installed first from its CPU build so that nothing pulls in CUDA packages.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
stamp=.venv/.terrapref-installed
want=$(cat pyproject.toml requirements.lock | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setting up .venv (pinned dependencies from requirements.lock) ..."
  .venv/bin/python -m pip install --quiet --disable-pip-version-check "torch==2.13.0"
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -c requirements.lock -e ".[all,test]"
  # Compile the numerical loops now (kept beside their sources) rather than in the first job.
  .venv/bin/python -m terrapref.warm_up
  echo "$want" > "$stamp"
fi
# ROS 1 (Debian's packages) for `terrapref ros1` and its test; never fails the set-up.
bash scripts/setup_ros1.sh
