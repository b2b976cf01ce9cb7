"""Bit-for-bit checks under CPU settings: programs run by fresh interpreters under settings that
change how plain NumPy products and exponentials come out (BLAS kernel, SIMD level, thread count).

A test module with such a check names it in a module-level ``CPU_CHECK`` and takes the session
fixture ``cpu_outputs`` (tests/conftest.py), which runs every collected check in one interpreter
per setting: the imports are paid once per setting, not once per check and setting.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import platform
import subprocess
import sys
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

Setting = dict[str, str]
"""Extra environment of one fresh interpreter."""


def _cpu_flags() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            return f.read()
    except OSError:
        return ""


def _settings() -> list[Setting]:
    settings = [{}, {"OPENBLAS_NUM_THREADS": "1"}, {"OPENBLAS_NUM_THREADS": "2"}]
    if platform.machine().lower() in ("x86_64", "amd64"):
        # Kernels every x86_64 CPU can run (SSE3, AVX2), and NumPy without its AVX-512 code paths.
        settings += [{"OPENBLAS_CORETYPE": "Prescott"}, {"NPY_DISABLE_CPU_FEATURES": "X86_V4,AVX512_ICL,AVX512_SPR"}]
        if "avx2" in _cpu_flags():
            settings.append({"OPENBLAS_CORETYPE": "Haswell"})
    return settings


SETTINGS = _settings()
"""Every BLAS kernel, SIMD level and thread count this machine can be made to use."""

QUICK = [{}, {"OPENBLAS_CORETYPE": "Prescott"} if platform.machine().lower() in ("x86_64", "amd64") else {"OPENBLAS_NUM_THREADS": "2"}]
QUICK += [{"NUMBA_CPU_NAME": "generic"}]
"""The settings of the default test run (each costs a fresh interpreter; all with the tests' one
BLAS thread unless they say otherwise): the machine's kernels, an older BLAS kernel (on arm64
another thread count) and compiled loops for a generic CPU. Every setting of a check, in the
machine's own environment, runs in the slow tests."""


@dataclass(frozen=True)
class CpuCheck:
    """A program that prints what must not depend on the CPU, and the settings to run it under."""

    name: str
    code: str
    settings: tuple[tuple[tuple[str, str], ...], ...]

    @classmethod
    def of(cls, name: str, code: str, settings: list[Setting]) -> "CpuCheck":
        return cls(name, code, tuple(tuple(sorted(s.items())) for s in settings))

    def quick(self) -> "CpuCheck":
        """The check under those of its settings that are :data:`QUICK`."""
        quick = {tuple(sorted(s.items())) for s in QUICK}
        return CpuCheck(self.name, self.code, tuple(s for s in self.settings if s in quick))


def _run_all(code: list[tuple[str, str]]) -> dict[str, str]:
    """Run each (name, code) in turn in this interpreter; what each printed, by name."""
    printed = {}
    for name, text in code:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            exec(compile(text, f"<{name}>", "exec"), {"__name__": "__main__"})
        printed[name] = out.getvalue()
    return printed


_PROGRAM = """
import json, sys
sys.path.insert(0, {tests!r})
from cpu_settings import _run_all
print(json.dumps(_run_all({code!r})))
"""


def run_checks(checks: list[CpuCheck], environ: Mapping[str, str]) -> dict[str, list[tuple[Setting, str]]]:
    """Each check run under each of its settings, by check: (setting, what it printed), in the
    check's order of settings. One fresh interpreter per setting, in ``environ`` with the
    setting's variables added, runs every check that has the setting, as many at once as there
    are cores (the answers do not depend on what else runs, which is the point)."""
    settings = list(dict.fromkeys(s for check in checks for s in check.settings))
    tests = os.path.dirname(os.path.abspath(__file__))

    def one(setting: tuple[tuple[str, str], ...]) -> dict[str, str]:
        code = [(c.name, c.code) for c in checks if setting in c.settings]
        program = _PROGRAM.format(tests=tests, code=code)
        done = subprocess.run(
            [sys.executable, "-c", program], env={**environ, **dict(setting)}, capture_output=True, text=True, timeout=300
        )
        assert done.returncode == 0, done.stderr
        return json.loads(done.stdout.strip().splitlines()[-1])

    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        printed = dict(zip(settings, pool.map(one, settings)))
    return {c.name: [(dict(s), printed[s][c.name]) for s in c.settings] for c in checks}
