"""The core without its extras (terrapref.extras): every other module imports, and each command
that needs a missing extra says so in one line, exit code 2, naming the extra to install.

A fresh interpreter in which the extras' packages cannot be imported stands in for a core-only
install (scripts/check_core.sh checks a real one)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import terrapref
from synthetic_bag import robot_yaml, write_robot
from terrapref.extras import EXTRAS, MissingExtra, check, needs
from terrapref.learning.model_file import FORMAT
from terrapref.tensorfile import write_tensor_file

ROOT = Path(__file__).resolve().parents[1]

# Modules that are the extras' features themselves: importing one without its extra is the
# one-line error (checked below); every other module imports with the core alone.
GATED = ("terrapref.teleop", "terrapref.baselines.cnn", "terrapref.interop.onnx_export")

_CORE_ONLY = """
import contextlib, importlib, io, json, pathlib, sys
for name in {blocked!r}:
    sys.modules[name] = None  # as if not installed: importing it raises ModuleNotFoundError
import terrapref
from terrapref.cli import main
from terrapref.extras import MissingExtra

root = pathlib.Path(terrapref.__file__).parent
failed = []
for path in sorted(root.rglob("*.py")):
    name = ".".join(("terrapref", *path.relative_to(root).with_suffix("").parts)).removesuffix(".__init__")
    if not name.startswith({gated!r}):
        try:
            importlib.import_module(name)
        except Exception as exc:
            failed.append(f"{{name}}: {{type(exc).__name__}}: {{exc}}")
results = {{"imports": failed}}
for argv in {commands!r}:
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(argv)
    results[" ".join(argv)] = [rc, err.getvalue()]
try:
    from terrapref.interop.live import LiveView
    LiveView(port=0)
except MissingExtra as exc:
    results["LiveView"] = [2, f"error: {{exc}}\\n"]
print(json.dumps(results))
"""

COMMANDS = {
    ("drive", "teach_course"): "teleop",
    ("import", "drive.mcap", "--robot", "robot.yaml", "--out", "rec"): "robot",
    ("export", "c.safetensors", "--format", "onnx", "--out", "c.onnx"): "robot",
    ("evaluate", "c.safetensors", "gen:7", "--mcap", "--out", "ev_mcap"): "robot",
    ("evaluate", "c.safetensors", "gen:7", "--engine", "ray", "--out", "ev_ray"): "ray",
    ("evaluate", "cnn.safetensors", "gen:7", "--out", "ev_cnn"): "cnn",
    ("study", "--quick", "--out", "study"): "cnn",
    ("ros2", "--model", "c.safetensors", "--robot", "robot.yaml"): "ros2",
    ("play", "drive.mcap"): "ros2",
}


@pytest.fixture(scope="module")
def core_only(tmp_path_factory) -> dict:
    """What a fresh interpreter without any extra's package reports: failed imports, and each
    command's exit code and standard error."""
    work = tmp_path_factory.mktemp("core_only")
    write_robot(work / "robot.yaml", robot_yaml())
    (work / "drive.mcap").write_bytes(b"")
    # A CNN model file: loading it reaches the CNN baseline's code, which is all this needs.
    write_tensor_file(work / "cnn.safetensors", {"w": np.zeros(1, np.float32)}, {"format": FORMAT, "kind": "cnn"})
    blocked = sorted({p for packages in EXTRAS.values() for p in packages})
    code = _CORE_ONLY.format(blocked=blocked, gated=GATED, commands=[list(c) for c in COMMANDS])
    env = {**os.environ, "PYTHONPATH": str(Path(terrapref.__file__).parents[1])}  # this terrapref, whichever install it is
    done = subprocess.run([sys.executable, "-c", code], cwd=work, capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_every_module_but_the_extras_own_imports_with_the_core_alone(core_only):
    assert core_only["imports"] == []


@pytest.mark.parametrize("argv, extra", COMMANDS.items(), ids=[f"{c[0]}-{extra}" for c, extra in COMMANDS.items()])
def test_a_command_that_needs_a_missing_extra_names_it_in_one_line(core_only, argv, extra):
    rc, err = core_only[" ".join(argv)]
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, err
    assert lines[0].startswith("error: ") and f"needs the {extra} extra: pip install 'terrapref[{extra}]'" in lines[0], err


def test_the_live_view_names_the_robot_extra(core_only):
    rc, err = core_only["LiveView"]
    assert "needs the robot extra" in err and "foxglove is not installed" in err


def test_the_extras_are_pyprojects():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    assert set(extras) == set(EXTRAS) | {"all", "test"}
    assert extras["all"] == [f"terrapref[{','.join(EXTRAS)}]"]
    for name, packages in EXTRAS.items():  # each importable package comes from a distribution of its extra
        distributions = {d.split("==")[0].lower() for d in extras[name]}
        assert all({"foxglove": "foxglove-sdk"}.get(p, p) in distributions for p in packages), name
    core = {d.split("==")[0].lower() for d in project["dependencies"]}
    assert not core & {d.split("==")[0].lower() for name in EXTRAS for d in extras[name]}


def test_needs_names_the_extra_and_what_is_missing(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(MissingExtra) as caught:
        with needs("ray", "--engine ray"):
            import ray  # noqa: F401
    assert caught.value.lines() == ["--engine ray: needs the ray extra: pip install 'terrapref[ray]' (ray is not installed)"]
    with pytest.raises(MissingExtra, match="ray is not installed"):
        check("ray", "--engine ray")
    with pytest.raises(ZeroDivisionError):  # only import errors are the extra's
        with needs("ray", "--engine ray"):
            1 / 0


@pytest.mark.slow
def test_the_core_installs_and_works_without_its_extras():
    """A real core-only install in a fresh environment (a few minutes; needs the package index)."""
    done = subprocess.run(
        ["bash", str(ROOT / "scripts" / "check_core.sh")],
        capture_output=True,
        text=True,
        timeout=1800,
        env={**os.environ, "PYTHON": sys.executable},
    )
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-4000:]
