"""The offset rule's class prices fitted with each situation of the drives left out in turn.

Reads a dataset `terrapref featurize` wrote and the recordings it was made from (by default
where the dataset says they were; else given in the order they were featurised). Each frame belongs to the scored situation (zone) of its recording's course whose middle
lies from 8 m behind to 12 m ahead of the vehicle along the path, the nearest to 2 m ahead. The
offset utility is fitted as `train` fits it, once on every frame and once without each
situation's frames, and the class prices are printed on the detour's scale, in the order the
drives declared, lethal classes left out (or ``--order``), with the steps between them: which
situations hold a step up and which hold it down (docs/lab/2026-12-07-the-strip-the-driver-keeps.md).

    python scripts/fit_by_situation.py D.safetensors [REC ...] [--order mud,rock,water]
"""

from __future__ import annotations

import argparse

import numpy as np

from terrapref.dataset import load_dataset, on_map
from terrapref.demos.recording import read_recording
from terrapref.errors import UserError
from terrapref.evaluation.speed import zone_spans
from terrapref.rules.offset.features import RELIEF_BANDS_DEG
from terrapref.rules.offset.fit import fit_offset_utility
from terrapref.rules.offset.geometry import OffsetGeometry
from terrapref.scenario.loader import parse_scenario
from terrapref.scenario.path import PathTracker, ReferencePath

BEHIND_M, AHEAD_M, AIM_M = 8.0, 12.0, 2.0  # a frame's situation: its middle this far behind to ahead, nearest AIM_M ahead


def situations(folder: str) -> tuple[np.ndarray, list[str]]:
    """Each kept frame's situation in the recording ``folder`` (an index into the labels; -1: none) and
    the labels: the zones the path crosses, each at the middle of its stretch of the path."""
    rec = read_recording(folder)
    scenario = parse_scenario(rec.scenario, f"{folder}/scenario.yaml", rec.classes, driven=True)
    poses = rec.poses[on_map(rec.poses, scenario)]
    path = ReferencePath(scenario.waypoints)
    tracker = PathTracker(path, back_m=2.0, ahead_m=6.0)
    progress = np.array([tracker.update(p[:2]) for p in poses])
    spans = zone_spans(scenario)
    ahead = np.array([(first + last) / 2 for _, first, last in spans])[None, :] - progress[:, None]
    near = (ahead > -BEHIND_M) & (ahead < AHEAD_M)
    which = np.argmin(np.where(near, np.abs(ahead - AIM_M), np.inf), axis=1)
    return np.where(near.any(axis=1), which, -1), [name for name, _, _ in spans]


def prices(arrays: dict, offsets: np.ndarray, keep: np.ndarray, columns: list[int]) -> np.ndarray:
    """The prices of the ``columns``' classes on the detour's scale, fitted to the frames ``keep``."""
    relief = (arrays["relief_m"][keep], RELIEF_BANDS_DEG) if "relief_m" in arrays else None  # as the rule's fit reads a drive on relief
    weights = fit_offset_utility(arrays["features"][keep], arrays["near_m"][keep], arrays["intent_m"][keep], offsets, relief=relief).weights
    return weights[columns] / weights[-2]


def main() -> None:
    try:
        run()
    except (UserError, OSError, ValueError) as exc:  # a file that is not what it should be: one line
        raise SystemExit(f"fit_by_situation: {exc}") from None


def run() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", help="the dataset terrapref featurize wrote of the recordings")
    parser.add_argument("recordings", nargs="*", help="the recordings, in the order they were featurised (default: where the dataset says)")
    parser.add_argument("--order", help="the classes to print, comma-separated (default: the drives' declared order)")
    args = parser.parse_args()
    data = load_dataset(args.dataset)
    if data.rule_data("offset") is None:
        raise SystemExit(f"{args.dataset}: holds no offset rule's arrays (featurised for another recipe)")
    config, arrays = data.rule_data("offset")
    offsets = OffsetGeometry.from_dict(config["geometry"]).offsets
    names = data.meta["features"]["feature_classes"]
    lethal = {*data.meta["classes"]["lethal"], "lethal"}  # the lethal classes, and the column they share
    order = args.order.split(",") if args.order else [c for c in data.meta.get("profile") or names if c in names and c not in lethal]
    if unknown := [c for c in order if c not in names]:
        raise SystemExit(f"--order: {', '.join(unknown)} not among the dataset's terrain columns ({', '.join(names)})")
    columns = [names.index(c) for c in order]
    recordings = args.recordings or [entry["path"] for entry in data.meta["recordings"]]
    if len(recordings) != len(data.meta["recordings"]):
        raise SystemExit(f"{args.dataset}: made of {len(data.meta['recordings'])} recording(s), {len(recordings)} given")
    which, labels = np.full(len(data), -1), []
    for k, folder in enumerate(recordings):
        mine, theirs = situations(folder)
        if (data.source == k).sum() != len(mine):
            raise SystemExit(f"{args.dataset}: recording {k} has {(data.source == k).sum()} frames, {folder} {len(mine)}")
        which[data.source == k] = np.where(mine >= 0, mine + len(labels), -1)
        labels += [f"{k}:{label}" for label in theirs]

    def row(name: str, keep: np.ndarray) -> str:
        p = prices(arrays, offsets, keep, columns)
        return (
            f"{name[:44]:44s} {int((~keep).sum()):5d}  "
            + " ".join(f"{v:6.1f}" for v in p)
            + "  steps "
            + " ".join(f"{v:5.1f}" for v in np.diff(p))
        )

    print(f"{'left out':44s} {'frames':>5s}  " + " ".join(f"{c[:6]:>6s}" for c in order))
    print(row("nothing", np.ones(len(data), dtype=bool)))
    for k, label in enumerate(labels):
        print(row(label, which != k))


if __name__ == "__main__":
    main()
