"""Import throughput: a ~520 MB synthetic robot log (raw mono8 label images at 30 Hz) as MCAP and
as a ROS 1 bag, each imported by `terrapref import` in a fresh process; MB/s of bag and peak
resident memory of that process. Also the Gymnasium environment's step rate.

    .venv/bin/python benchmarks/bench_import.py [--repeat 3] [--out DIR]
"""

from __future__ import annotations

import argparse
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _size(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*")) if path.is_dir() else path.stat().st_size


def _import_once(bag: Path, robot: Path, out: Path) -> tuple[float, float]:
    """Wall seconds and peak resident MB of one `terrapref import` in its own process."""
    shutil.rmtree(out, ignore_errors=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "terrapref.cli", "import", str(bag), "--robot", str(robot), "--out", str(out)],
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    wall = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return wall, max(peak, before) / 1024.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--out", type=Path, default=None, help="work folder (default: a temporary one, removed after)")
    args = parser.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the tests' generator of robot logs
    from synthetic_bag import robot_yaml, write_robot, write_synthetic_bag
    from terrapref.demos.recording import read_recording

    work = args.out or Path(tempfile.mkdtemp(prefix="terrapref-bench-import-"))
    work.mkdir(parents=True, exist_ok=True)
    robot = work / "robot.yaml"
    write_robot(robot, robot_yaml())  # and the label map it names
    print("| log | size | import wall (median of %d) | throughput | peak memory |" % args.repeat)
    print("|---|---|---|---|---|")
    try:
        for storage, name in (("mcap", "big.mcap"), ("rosbag1", "big.bag")):
            bag = work / name
            if not bag.exists():
                write_synthetic_bag(bag, storage, scenario="demo_course", seed=0, encoding="mono8", repeat_images=3)
            mb = _size(bag) / 1e6
            runs = [_import_once(bag, robot, work / f"rec_{storage}") for _ in range(args.repeat)]
            wall = statistics.median(r[0] for r in runs)
            peak = max(r[1] for r in runs)
            frames = len(read_recording(work / f"rec_{storage}"))
            print(
                f"| {storage}, 640x480 mono8 at 30 Hz, {frames} frames kept at 10 Hz | {mb:.0f} MB | {wall:.2f} s "
                f"(range {min(r[0] for r in runs):.2f}-{max(r[0] for r in runs):.2f}) | {mb / wall:.0f} MB/s | {peak:.0f} MB |"
            )
        import gymnasium as gym

        import terrapref.sim.env  # noqa: F401

        for kwargs in ({}, {"image_size": (64, 80), "image_encoding": "onehot"}, {"image_size": None}):
            env = gym.make("terrapref/OffRoadNav-v1", scenario="demo_course", **kwargs)
            env.reset(seed=0)
            env.action_space.seed(0)
            start, n = time.perf_counter(), 0
            while n < 2000:
                _, _, terminated, truncated, _ = env.step(env.action_space.sample())
                n += 1
                if terminated or truncated:
                    env.reset()
            print(f"env step {kwargs or 'default (120x160 ids)'}: {n / (time.perf_counter() - start):.0f} steps/s")
    finally:
        if args.out is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
