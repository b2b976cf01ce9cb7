#!/usr/bin/env bash
# Set up the environment if needed, check the code with the linter and the formatter (ruff,
# pinned), then run the default (fast) test suite, one worker per core (pytest-xdist; pass -n 0
# to run in one process, e.g. under a debugger). `ruff format src tests scripts benchmarks
# examples` formats what the check refuses.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check --quiet src tests scripts benchmarks examples
.venv/bin/ruff format --check --quiet src tests scripts benchmarks examples
# Bytecode is written even where the environment says not to: every worker imports the package
# and the tests, and many tests start fresh interpreters that import it again; compiling the
# sources each time costs the run a tenth of its time.
unset PYTHONDONTWRITEBYTECODE
exec .venv/bin/python -m pytest -q -n auto --dist worksteal "$@"
