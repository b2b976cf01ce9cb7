"""Exploratory study: featurise recordings, train C with a given recipe, drive every packaged course.

    python scripts/train_eval.py REC_DIR[,REC_DIR...] '{"epochs": 100, "skip": true}' [--seeds 1]

Prints each course's zone choices and the summary over the test set (test_course and the
figure variations). For diagnosis only: choosing a recipe by these numbers tunes it to the
test set; selection belongs on layouts that are not packaged.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from terrapref.dataset import build_dataset
from terrapref.demos.recording import read_recording
from terrapref.evaluation.runner import PLANNER, RunSpec, run_many, summarise
from terrapref.features import FeatureConfig
from terrapref.learning.pipeline import RunOptions, train_and_save
from terrapref.learning.train import TrainConfig
from terrapref.scenario import packaged_scenarios


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recordings")
    parser.add_argument(
        "config", help='TrainConfig changes as JSON, part by part, e.g. {"optimiser": {"epochs": 300}, "classifier": {"skip": true}}'
    )
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--profile", default="mud,rock,water,non_traversable")
    args = parser.parse_args()
    ds = build_dataset([read_recording(r) for r in args.recordings.split(",")], FeatureConfig())
    print(f"{len(ds)} samples")
    with tempfile.TemporaryDirectory() as tmp:
        model = str(Path(tmp) / "model.safetensors")
        r = train_and_save(ds, model, TrainConfig().updated(json.loads(args.config)), options=RunOptions(checkpoints=False))
        best = r.history[r.best_epoch - 1]
        print(f"epoch {r.best_epoch}: val loss {best.val_loss:.3f}, val acc {best.val_acc:.3f}, top-3 {best.val_top3:.3f}, {r.steps} steps")
        names = [n for n in packaged_scenarios() if n != "demo_course"]
        profile = tuple(args.profile.split(","))
        res = run_many([RunSpec(n, s, PLANNER, model, profile) for n in names for s in range(args.seeds)])
    for x in res:
        m = x.metrics
        zones = " ".join(f"{z.id}:{z.expect}->{z.choice}{'' if z.success else '(X)'}" for z in m.zones)
        print(f"{x.scenario:42s} seed {x.seed} collisions {m.collisions}  {zones}")
    print("test set:", summarise([x for x in res if x.scenario != "train_course"], PLANNER).to_dict())
    print("train_course:", summarise([x for x in res if x.scenario == "train_course"], PLANNER).to_dict())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
