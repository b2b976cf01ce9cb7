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
    """Load a scenario by packaged name (``train_course``), by path, or generate one (``gen:SEED``)."""
    if name_or_path.startswith("gen:"):
        from terrapref.scenario.generate import generate_course

        try:
            seed = int(name_or_path[4:])
        except ValueError:
            raise ScenarioError(name_or_path, "a generated course is named gen:SEED with an integer SEED") from None
        if not 0 <= seed < 2**63:
            raise ScenarioError(name_or_path, "a generated course's SEED is an integer >= 0")
        return generate_course(seed, classes=classes)
    return load_scenario(scenario_path(name_or_path), classes)


def _exists(p: Path) -> bool:
    # A name the OS refuses (too long, ...) is left for the loader to report as unreadable.
    try:
        return p.exists()
    except OSError:
        return True
