"""Simulator benchmarks: full-frame segmentation rendering and the closed simulation loop.

Run through ``scripts/bench.sh`` (which pins one core); the numbers it prints go into
``docs/benchmarks.md``. Not collected by pytest (the default run only looks in ``tests/``).

(a) render: one 640 x 480 frame on a 100 m x 100 m map at 0.05 m cells (2000 x 2000) filled with
    random classes, timed per frame at random poses; median over ``--poses`` (>= 500) frames.
    The same with relief (rolling ground, a mound, a pit, a ridge; the body resting on it at
    each pose): the frame and its depth image, every ray followed to the height field, each
    timed in turn with a flat frame at the same pose, whose median its target is set against.
(b) loop: ``Simulation.step`` with a constant command on the packaged ``demo_course``: three
    30 Hz vehicle ticks, collision checks, progress along the path and one frame per step,
    rendered whole (as a recording or a human's display reads it) or not at all (a frame is
    rendered only as far as it is read; the planner's share is in bench_demos); frames per
    second of simulated camera frames. Going straight from the start, the
    vehicle would leave the 60 m map after 58 s, so each episode is cut at 55 s (550 frames)
    and restarted, keeping every timed frame on the map.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time
from dataclasses import dataclass

import numpy as np
from reference import reference_ms  # benchmarks/reference.py (the script's folder is on sys.path)

from terrapref.camera import PinholeCamera, SegmentationRenderer
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation
from terrapref.terrain import default_classes
from terrapref.vehicle import Command, Pose, Vehicle
from terrapref.world import WorldMap

RENDER_TARGET_MS = 0.5


@dataclass(frozen=True)
class Timing:
    """Per-call wall times [s] of one benchmark."""

    samples: np.ndarray

    @property
    def median_ms(self) -> float:
        return float(np.median(self.samples) * 1e3)

    @property
    def p90_ms(self) -> float:
        return float(np.percentile(self.samples, 90) * 1e3)

    @property
    def mean_ms(self) -> float:
        return float(np.mean(self.samples) * 1e3)


def bench_render(n_poses: int, rng: np.random.Generator, size_m: float = 100.0, resolution_m: float = 0.05, warmup: int = 20) -> Timing:
    """Time full-frame renders at ``n_poses`` random poses on a random-terrain map."""
    n = round(size_m / resolution_m)
    classes = default_classes()
    ids = np.array([c.id for c in classes.classes], dtype=np.uint8)
    world = WorldMap(rng.choice(ids, size=(n, n)), resolution_m, classes)
    renderer = SegmentationRenderer(PinholeCamera(), world)
    poses = [
        Pose(float(x), float(y), float(a))
        for x, y, a in zip(rng.uniform(0, size_m, n_poses), rng.uniform(0, size_m, n_poses), rng.uniform(-math.pi, math.pi, n_poses))
    ]
    for pose in poses[:warmup]:
        renderer.render(pose)
    samples = np.empty(n_poses)
    for i, pose in enumerate(poses):
        t0 = time.perf_counter()
        renderer.render(pose)
        samples[i] = time.perf_counter() - t0
    return Timing(samples)


def bench_render_relief(
    n_poses: int, rng: np.random.Generator, size_m: float = 100.0, resolution_m: float = 0.05, warmup: int = 20
) -> tuple[Timing, Timing]:
    """Time full frames with their depth (``render_with_depth``) at ``n_poses`` random poses on a
    random-terrain map with relief: rolling ground (0.6 m of noise over 15 m) and a mound, a pit
    and a ridge, the body resting on the ground at each pose. Each relief frame is timed beside a
    flat frame at the same pose on a flat map of random terrain, the two in turn, so that their
    ratio holds however busy the machine is: (relief, flat beside it)."""
    from terrapref.scenario.relief import Mound, Noise, Ridge
    from terrapref.world.relief import height_field

    n = round(size_m / resolution_m)
    classes = default_classes()
    ids = np.array([c.id for c in classes.classes], dtype=np.uint8)
    relief = (
        Noise(amplitude_m=0.6, wavelength_m=15.0, seed=3),
        Mound(center=(30.0, 40.0), radius_m=4.0, height_m=1.0),
        Mound(center=(60.0, 60.0), radius_m=3.0, height_m=-0.6),
        Ridge(polyline=np.array([[20.0, 70.0], [80.0, 75.0]]), width_m=3.0, height_m=0.8),
    )
    world = WorldMap(rng.choice(ids, size=(n, n)), resolution_m, classes, height_field(relief, (n, n), resolution_m))
    renderer = SegmentationRenderer(PinholeCamera(), world)
    flat = SegmentationRenderer(PinholeCamera(), WorldMap(rng.choice(ids, size=(n, n)), resolution_m, classes))
    poses = [
        Pose(float(x), float(y), float(a))
        for x, y, a in zip(rng.uniform(0, size_m, n_poses), rng.uniform(0, size_m, n_poses), rng.uniform(-math.pi, math.pi, n_poses))
    ]
    bodies = [Vehicle(pose, ground=world).attitude for pose in poses]
    for pose, attitude in zip(poses[:warmup], bodies):
        renderer.render_with_depth(pose, attitude)
        flat.render(pose)
    samples, beside = np.empty(n_poses), np.empty(n_poses)
    for i, (pose, attitude) in enumerate(zip(poses, bodies)):
        t0 = time.perf_counter()
        renderer.render_with_depth(pose, attitude)
        t1 = time.perf_counter()
        flat.render(pose)
        beside[i], samples[i] = time.perf_counter() - t1, t1 - t0
    return Timing(samples), Timing(beside)


def bench_loop(
    n_frames: int,
    command: Command = Command(1.0, 0.0),
    scenario: str = "demo_course",
    episode_frames: int = 550,
    warmup: int = 10,
    whole_frame: bool = True,
) -> Timing:
    """Time ``Simulation.step`` with a constant command, restarting after ``episode_frames`` or when done.

    With ``whole_frame`` each step's image is rendered in full, as a recorder reads it.
    """
    sim = Simulation(resolve_scenario(scenario))
    sim.reset()
    for _ in range(warmup):
        sim.step(command)
    sim.reset()
    samples = np.empty(n_frames)
    for i in range(n_frames):
        t0 = time.perf_counter()
        frame = sim.step(command)
        if whole_frame:
            frame.image  # noqa: B018 - renders the frame
        samples[i] = time.perf_counter() - t0
        if sim.done or sim.frame_index >= episode_frames:
            sim.reset()  # not timed: a restart is not a simulated frame
    return Timing(samples)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=1000, help="random poses for the render benchmark (>= 500)")
    parser.add_argument("--frames", type=int, default=1000, help="Simulation.step calls for the loop benchmark")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random map and poses")
    args = parser.parse_args(argv)
    if args.poses < 500:
        parser.error("--poses must be >= 500")

    ref = reference_ms()
    rng = np.random.default_rng(args.seed)
    render = bench_render(args.poses, rng)
    relief, beside = bench_render_relief(args.poses, rng)
    loop = bench_loop(args.frames)
    bare = bench_loop(args.frames, whole_frame=False)

    threads = os.environ.get("OMP_NUM_THREADS", "unset")
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else "?"
    print(
        f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}, "
        f"{os.cpu_count()} CPUs, pinned to {affinity}, OMP_NUM_THREADS={threads}"
    )
    rows = [
        ("benchmark", "median", "p90", "mean", "rate", "median / reference", "target"),
        ("reference: naive NumPy render, one ray per pixel (benchmarks/reference.py)", f"{ref:.3f} ms", "-", "-", "-", "1", "-"),
        (
            f"render 640x480, 100 m map @ 0.05 m ({args.poses} poses)",
            f"{render.median_ms:.3f} ms",
            f"{render.p90_ms:.3f} ms",
            f"{render.mean_ms:.3f} ms",
            f"{1e3 / render.median_ms:.0f} fps",
            f"{render.median_ms / ref:.4f}",
            f"<= {RENDER_TARGET_MS:g} ms: {'met' if render.median_ms <= RENDER_TARGET_MS else 'MISSED'}",
        ),
        (
            f"render 640x480 with its depth, on relief, 100 m map @ 0.05 m ({args.poses} poses)",
            f"{relief.median_ms:.3f} ms",
            f"{relief.p90_ms:.3f} ms",
            f"{relief.mean_ms:.3f} ms",
            f"{1e3 / relief.median_ms:.0f} fps",
            f"{relief.median_ms / ref:.4f}",
            f"<= 3x the flat frame's ({relief.median_ms / beside.median_ms:.1f}x a flat frame's {beside.median_ms:.3f} ms, "
            + "timed in turn with it): "
            + ("met" if relief.median_ms <= 3 * beside.median_ms else "MISSED"),
        ),
        (
            f"Simulation.step + whole frame, demo_course ({args.frames} frames)",
            f"{loop.median_ms:.3f} ms",
            f"{loop.p90_ms:.3f} ms",
            f"{loop.mean_ms:.3f} ms",
            f"{len(loop.samples) / loop.samples.sum():.0f} fps",
            f"{loop.median_ms / ref:.4f}",
            "-",
        ),
        (
            f"Simulation.step, frame not read, demo_course ({args.frames} frames)",
            f"{bare.median_ms:.3f} ms",
            f"{bare.p90_ms:.3f} ms",
            f"{bare.mean_ms:.3f} ms",
            f"{len(bare.samples) / bare.samples.sum():.0f} fps",
            f"{bare.median_ms / ref:.4f}",
            "-",
        ),
    ]
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for k, row in enumerate(rows):
        print("| " + " | ".join(cell.ljust(w) for cell, w in zip(row, widths)) + " |")
        if k == 0:
            print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
