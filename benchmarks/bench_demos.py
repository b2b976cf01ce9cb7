"""Demonstration-side benchmarks: utility features per frame, and recording train_course.

Run through ``scripts/bench.sh`` (one core); numbers go into ``docs/benchmarks.md``.

(a) features: ``UtilityFeaturizer`` (m = 21, n = 30, look-ahead distance utility) on real
    frames of ``train_course`` driven by the synthetic driver; each call timed on its own; the
    median is reported. Target: <= 30 us median.
(c) decision: ``Planner.decide`` (features + classifier C in NumPy + progress along the path)
    on the same frames, with a model trained on the recording (paper recipe). Target:
    <= 100 us median. Three more lines: a 2-member ensemble, the planner's second
    stage (terrapref.rules.second.rule) as in recipe ``ours``, and the decision of recipe
    ``teach`` (an ensemble of three with the second stage, then with the offset rule too, which
    drives recipe ``teach``, the default: target <= 150 us; the stage weight does not change
    the cost).
(d) closed loop: the planner (same model) driving ``train_course`` in the simulation, frames
    rendered only where the planner reads them; simulated frames per second of wall time.
(b) record: ``terrapref record train_course`` end to end through the library (simulation,
    synthetic driver, PNG frames and the JSONL log written to a temporary directory), wall time.
    Target: <= 20 s.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from reference import reference_ms  # benchmarks/reference.py (the script's folder is on sys.path)

from terrapref.camera import CameraConfig, PinholeCamera
from terrapref.demos.expert import ExpertDriver
from terrapref.demos.meta import ExpertInfo, RecordingMeta, RecordingSetup
from terrapref.demos.recording import RecordingWriter, read_recording
from terrapref.demos.session import RunSettings, record_run
from terrapref.features import FeatureConfig, PreferenceSetConfig, UtilityFeaturizer
from terrapref.rules import OffsetConfig, SecondStageConfig, SpeedConfig
from terrapref.scenario import resolve_scenario
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.sim import SimConfig, Simulation
from terrapref.terrain import PreferenceProfile


def bench_record(out: Path, seed: int) -> tuple[float, int, int]:
    scenario = resolve_scenario("train_course")
    camera, pref, sim_cfg = CameraConfig(), PreferenceSetConfig(), SimConfig()
    meta = RecordingMeta.driven(scenario, RecordingSetup(camera, pref, sim_cfg), ExpertInfo(seed), PreferenceProfile.default())
    t0 = time.perf_counter()
    sim = Simulation(scenario, camera, sim_cfg)
    writer = RecordingWriter(out, meta, scenario.to_dict())
    record_run(sim, ExpertDriver(), writer, RunSettings(pref), np.random.default_rng(seed))
    wall = time.perf_counter() - t0
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    return wall, writer.count, size


def bench_features(rec_dir: Path, repeats: int) -> np.ndarray:
    rec = read_recording(rec_dir)
    images = [rec.image(i) for i in range(0, len(rec), max(1, len(rec) // 500))]
    idx = list(range(0, len(rec), max(1, len(rec) // 500)))
    featurizer = UtilityFeaturizer(FeatureConfig(), PinholeCamera(CameraConfig()))
    path = ReferencePath(np.asarray(rec.meta["path"]))
    tracker = PathTracker(path)
    progress = [tracker.update(rec.poses[i, :2]) for i in idx]
    times = []
    for _ in range(repeats):
        for image, i, s in zip(images, idx, progress):
            pose = tuple(rec.poses[i])
            t0 = time.perf_counter()
            featurizer(image, pose, path, s)
            times.append(time.perf_counter() - t0)
    return np.array(times)


def bench_closed_loop(model_path: Path) -> tuple[float, int]:
    from terrapref.learning.model_file import load_model
    from terrapref.planner import Planner, PlannerDriver
    from terrapref.sim import run_episode

    sim = Simulation(resolve_scenario("train_course"))
    driver = PlannerDriver(Planner(load_model(model_path)))
    t0 = time.perf_counter()
    log = run_episode(sim, driver, np.random.default_rng(0))
    return time.perf_counter() - t0, len(log.commands)


def bench_decision(rec_dir: Path, repeats: int, features: FeatureConfig | None = None, members: int = 1, rules: tuple = ()) -> np.ndarray:
    from terrapref.dataset import build_dataset
    from terrapref.learning.model_file import load_model
    from terrapref.learning.network import ClassifierConfig
    from terrapref.learning.pipeline import RunOptions, train_and_save
    from terrapref.learning.train import TrainConfig
    from terrapref.planner import Planner

    rec = read_recording(rec_dir)
    features = features or FeatureConfig()
    plain = features == FeatureConfig() and members == 1 and not rules
    model_path = rec_dir.parent / ("model.safetensors" if plain else "variant.safetensors")
    train_and_save(
        build_dataset([rec], features, rules=rules),
        model_path,
        TrainConfig(classifier=ClassifierConfig(members=members)),
        rules=rules,
        options=RunOptions(checkpoints=False),
    )
    planner = Planner(load_model(model_path))
    idx = list(range(0, len(rec), max(1, len(rec) // 500)))
    images = [rec.image(i) for i in idx]
    times = []
    for _ in range(repeats):
        planner.set_path(np.asarray(rec.meta["path"]))
        for image, i in zip(images, idx):
            pose = tuple(rec.poses[i])
            t0 = time.perf_counter()
            planner.decide(image, pose)
            times.append(time.perf_counter() - t0)
    return np.array(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "rec"
        wall, frames, size = bench_record(out, args.seed)
        t = bench_features(out, args.repeats)
        d = bench_decision(out, args.repeats)
        d2 = bench_decision(out, args.repeats, members=2)
        d3 = bench_decision(out, args.repeats, rules=(SecondStageConfig(),))
        d4 = bench_decision(out, args.repeats, members=3, rules=(SecondStageConfig(),))
        d5 = bench_decision(out, args.repeats, members=3, rules=(SecondStageConfig(), OffsetConfig()))
        d6 = bench_decision(out, args.repeats, members=3, rules=(SecondStageConfig(), OffsetConfig(), SpeedConfig()))
        loop_s, loop_frames = bench_closed_loop(out.parent / "model.safetensors")
    ref_s = reference_ms() / 1e3

    def line(name: str, samples: np.ndarray, target: str) -> None:
        med = float(np.median(samples))
        print(
            f"{name:48s} {med * 1e6:8.1f}us {np.percentile(samples, 90) * 1e6:8.1f}us {med / ref_s:10.5f} {target:>10s}   ({len(samples)} calls)"
        )

    print(f"{'benchmark':48s} {'median':>10s} {'p90':>10s} {'/reference':>10s} {'target':>10s}")
    print(f"{'reference: naive NumPy render (reference.py)':48s} {ref_s * 1e3:8.2f}ms {'':>10s} {1:10d} {'-':>10s}")
    line("features U (m=21, n=30), per frame", t, "<= 30us")
    line("decision (features + C + progress), per frame", d, "<= 100us")
    line("decision, 2 members, per frame", d2, "-")
    line("decision with the second stage, per frame", d3, "-")
    line("decision of recipe teach, C + second stage", d4, "<= 60us")
    line("teach, offset rule drives, without the speed rule", d5, "-")
    line("the default decision: teach, offset + speed rules", d6, "<= 150us")
    print(
        f"{'planner driving train_course, closed loop':48s} {loop_s:9.2f}s {'':>10s} {loop_s / ref_s:10.1f} {'-':>10s}   "
        f"({loop_frames} frames, {loop_frames / loop_s:.0f} frames/s)"
    )
    print(
        f"{'record train_course (synthetic driver)':48s} {wall:9.2f}s {'':>10s} {wall / ref_s:10.1f} {'<= 20s':>10s}   "
        f"({frames} frames, {size / 1e6:.1f} MB, {size / frames / 1e3:.1f} kB/frame)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
