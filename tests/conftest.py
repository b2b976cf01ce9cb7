"""Fixtures shared across test modules, built once per test run."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def fig7_recording(tmp_path_factory) -> Path:
    """An undisturbed recording of the synthetic driver on fig7_rock_vs_non_traversable_left
    (about 600 frames, up to the rock and the trees). Shared: read it, never write into it."""
    from terrapref.cli import main

    out = tmp_path_factory.mktemp("fig7") / "rec"
    assert main(["record", "fig7_rock_vs_non_traversable_left", "--out", str(out), "--quiet", "--disturb", "0"]) == 0
    return out


@pytest.fixture(scope="session")
def cpu_outputs(request) -> dict:
    """What each module's bit-for-bit check (its ``CPU_CHECK``, tests/cpu_settings.py) printed
    under each of its CPU settings, by check name: one fresh interpreter per setting runs the
    checks of every collected test that takes this fixture."""
    from cpu_settings import run_checks

    checks = {item.module.CPU_CHECK for item in request.session.items if "cpu_outputs" in getattr(item, "fixturenames", ())}
    return run_checks(sorted(checks, key=lambda c: c.name))
