"""Summaries of recordings: what `terrapref inspect` prints and draws."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from terrapref.demos.recording import Recording
from terrapref.evaluation.scoring import ZoneResult, score_zones
from terrapref.scenario import Scenario, parse_scenario
from terrapref.terrain import PreferenceProfile
from terrapref.vehicle import ControlSet
from terrapref.world import WorldMap, rasterise


@dataclass(frozen=True)
class RecordingSummary:
    frames: int
    duration_s: float
    complete: bool
    label_counts: np.ndarray  # (m,)
    control: ControlSet
    zones: list[tuple[ZoneResult, bool]]  # (result, reached)
    scenario: Scenario
    world: WorldMap
    quit: bool = False  # the person ended the drive (Esc) before the goal
    lethal_contact: str | None = None  # what the drive's summary says of lethal terrain under the vehicle
    order: tuple[str, ...] | None = None  # the driver's declared preference order; None: the recording declares none
    run: dict | None = None  # what the drive's summary in meta.json says of it (None: a log that holds none)

    @property
    def status(self) -> str:
        if not self.complete:
            return "partial"
        return "quit by the driver" if self.quit else "complete"

    @property
    def outcome(self) -> str | None:
        """How the drive ended, as its summary says: whether it reached the goal and, on relief, its
        tips, times stuck and largest roll and pitch; None where the recording holds no summary."""
        run = self.run or {}
        if "completed" not in run:
            return None
        text = "reached the goal" if run["completed"] else "did not reach the goal"
        if "tips" in run or "stuck" in run:
            text += f"; {run.get('tips', 0)} tips, {run.get('stuck', 0)} times stuck"
        if "max_roll_deg" in run and "max_pitch_deg" in run:
            text += f"; roll at most {float(run['max_roll_deg']):.1f} deg, pitch {float(run['max_pitch_deg']):.1f} deg"
        return text

    def lines(self) -> list[str]:
        out = [
            f"status     {self.status}",
            f"frames     {self.frames}",
            f"duration   {self.duration_s:.1f} s",
            *([f"drive      {self.outcome}"] if self.outcome else []),
            f"scenario   {self.scenario.name}",
            f"order      {' > '.join(self.order)}"
            if self.order
            else "order      none declared (zones are scored under the class table's order; training needs the driver's)",
            "labels     (index: w [rad/s]  count)",
        ]
        at = 4 + bool(self.outcome)  # after the scenario's line
        if not self.scenario.has_terrain:
            out.insert(at, "map        none: the log holds the path and the driven poses, not the ground (the figure draws those alone)")
        if self.lethal_contact is not None:
            out.insert(at + 1, f"lethal     the drive had lethal terrain under the vehicle: {self.lethal_contact}")
        peak = max(int(self.label_counts.max()), 1)
        for i, n in enumerate(self.label_counts):
            out.append(f"  {i:3d}: {self.control.w_rps[i]:+5.2f}  {int(n):6d}  {'#' * round(40 * int(n) / peak)}")
        if self.zones:
            out.append("zones      (id, label: expected -> choice)")
            # Columns as wide as their longest entry: a long label (a triple of long class names) keeps the table in line.
            label_w = max(len(z.label) for z, _ in self.zones)
            expect_w = max(len(z.expect) for z, _ in self.zones)
            choice_w = max(len(z.choice if r else "-") for z, r in self.zones)
            for z, reached in self.zones:
                verdict = ("ok" if z.success else "MISS") if reached else "not reached"
                choice = z.choice if reached else "-"
                out.append(f"  {z.id:>4s} {z.label:{label_w}s} {z.expect:>{expect_w}s} -> {choice:<{choice_w}s} {verdict}")
            scored = [z for z, r in self.zones if r]
            out.append(f"zone success {sum(z.success for z in scored)}/{len(scored)} reached ({len(self.zones)} zones)")
        return out


def summarise(recording: Recording) -> RecordingSummary:
    """Label histogram and zone choices (SPEC 12) of a recording, under its own profile."""
    meta = recording.meta
    classes = recording.classes
    scenario = parse_scenario(recording.scenario, str(recording.path / "scenario.yaml"), classes, driven=True)
    world = rasterise(scenario)
    profile = PreferenceProfile.parse(meta.get("profile") or list(classes.profile), classes, source=str(recording.path / "meta.json"))
    control = ControlSet.from_dict(meta["preference_set"]["control"]) if meta.get("preference_set") else ControlSet()  # as train reads it
    counts = np.bincount(recording.labels, minlength=control.m)[: control.m]
    zones = [(z, z.reached) for z in score_zones(recording.poses, scenario, world, profile)]
    run = meta.get("summary") if isinstance(meta.get("summary"), dict) else {}
    return RecordingSummary(
        len(recording),
        recording.duration_s,
        recording.complete,
        counts,
        control,
        zones,
        scenario,
        world,
        quit=bool(run.get("quit")),
        lethal_contact=recording.lethal_contact(),
        order=tuple(meta["profile"]) if meta.get("profile") else None,
        run=run,
    )


def save_driven_path(summary: RecordingSummary, recording: Recording, out: str | Path) -> Path:
    from terrapref.plots import save_map

    status = summary.status
    missed = {z.id: f"missed: expected {z.expect}, drove {z.choice}" for z, reached in summary.zones if reached and not z.success}
    return save_map(
        out,
        summary.scenario,
        summary.world,
        [("driven", recording.poses[:, :2], "red")],
        title=f"{summary.scenario.name}: {recording.path.name} ({status}, {summary.frames} frames"
        + (f"; {summary.outcome}" if summary.outcome else "")
        + ")",
        marks=missed,
    )
