"""Packaged scenarios, addressable by name wherever a command takes a SCENARIO."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from terrapref.errors import ScenarioError
from terrapref.scenario.loader import load_scenario
from terrapref.scenario.model import Scenario
from terrapref.terrain import ClassTable


def packaged_scenarios() -> list[str]:
    """Names of the scenarios shipped with terrapref, sorted."""
    folder = resources.files("terrapref") / "data" / "scenarios"
    return sorted(p.name[: -len(".yaml")] for p in folder.iterdir() if p.name.endswith(".yaml"))


def scenario_path(name_or_path: str) -> Path:
    """A packaged scenario's file, or ``name_or_path`` itself when it names an existing file."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or "/" in name_or_path or _exists(p):
        return p
    if name_or_path in packaged_scenarios():
        ref = resources.files("terrapref") / "data" / "scenarios" / f"{name_or_path}.yaml"
        return Path(str(ref))
    raise ScenarioError(
        name_or_path, f"no such file and no packaged scenario of that name; packaged: {', '.join(packaged_scenarios()) or 'none'}"
    )


def resolve_scenario(name_or_path: str, classes: ClassTable | None = None) -> Scenario:
    """Load a scenario by packaged name (``train_course``), by path, or generate one (``gen:SEED``;
    ``genrelief:SEED``: the same layout with relief of the same seed)."""
    for prefix in ("gen:", "genrelief:"):
        if name_or_path.startswith(prefix):
            return _generated(name_or_path, prefix, classes)
    return load_scenario(scenario_path(name_or_path), classes)


def _generated(name: str, prefix: str, classes: ClassTable | None) -> Scenario:
    """The generated course ``name`` (``gen:SEED`` or ``genrelief:SEED``)."""
    from terrapref.scenario.generate import generate_course

    digits = name[len(prefix) :]
    if not (digits.isascii() and digits.isdigit()):  # int() would take " 3", "3_0" and "+3" too: other names of a course
        raise ScenarioError(name, f"a generated course is named {prefix}SEED with an integer SEED (digits only)")
    seed = int(digits)
    if not 0 <= seed < 2**63:
        raise ScenarioError(name, "a generated course's SEED is an integer from 0 to 2^63 - 1")
    course = generate_course(seed, classes=classes)
    if prefix == "gen:":
        return course
    from terrapref.scenario.relief_layout import with_relief

    return with_relief(course, seed, f"genrelief_{seed}")


def _exists(p: Path) -> bool:
    # A name the OS refuses (too long, ...) is left for the loader to report as unreadable.
    try:
        return p.exists()
    except OSError:
        return True
