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
# The compiled loops are cached beside their sources, and a cache names the modules its types
# came from: one written before a module moved cannot be read after. A cache is also kept while
# its own file is unchanged, though a loop it inlined from another file changed. When the
# package's modules move or a module with compiled loops changes (a pull, a checkout, an edit),
# the caches are removed and the loops compiled again.
modules=$( (find src/terrapref -name '*.py' | sort; grep -rl --include='*.py' numba src/terrapref | sort | xargs sha256sum) | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setting up .venv (pinned dependencies from requirements.lock) ..."
  .venv/bin/python -m pip install --quiet --disable-pip-version-check "torch==2.13.0"
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -c requirements.lock -e ".[all,test]"
  echo "$want" > "$stamp"
fi
if [ "$(cat .venv/.terrapref-modules 2>/dev/null)" != "$modules" ]; then
  find src/terrapref -path '*/__pycache__/*' \( -name '*.nbi' -o -name '*.nbc' \) -delete
  # Compile the package's bytecode and its numerical loops now (kept beside their sources)
  # rather than in the first job, as an installed package's would be.
  .venv/bin/python -m compileall -q src/terrapref
  .venv/bin/python -m terrapref.warm_up
  echo "$modules" > .venv/.terrapref-modules
fi
# The tests' bytecode too: pytest compiles each test module with its asserts rewritten and
# keeps the result beside it; made here, on a fresh clone, rather than by every worker of the
# first test run. Done again when a test file changes (pytest itself recompiles any stale one);
# a test file that does not compile is left for the test run to report.
tests=$(find tests -name '*.py' | sort | xargs sha256sum | sha256sum | cut -d' ' -f1)
if [ "$(cat .venv/.terrapref-tests 2>/dev/null)" != "$tests" ]; then
  if env -u PYTHONDONTWRITEBYTECODE .venv/bin/python -m pytest -q --collect-only -p no:xdist \
    -p no:cacheprovider > /dev/null 2>&1; then
    echo "$tests" > .venv/.terrapref-tests
  fi
fi
# ROS 1 (Debian's packages) for `terrapref ros1` and its test; never fails the set-up.
bash scripts/setup_ros1.sh
