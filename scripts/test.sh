#!/usr/bin/env bash
# Set up the environment if needed, then run the default (fast) test suite, one worker per core
# (pytest-xdist; pass -n 0 to run in one process, e.g. under a debugger).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/python -m pytest -q -n auto --dist worksteal "$@"
