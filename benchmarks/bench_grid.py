"""Grid throughput: closed-loop evaluation runs per second against workers, local processes and Ray.

The jobs are the ones `terrapref evaluate` and `terrapref select` run: the synthetic driver
driving generated layouts (``gen:1000`` on), each run independent. Each engine and worker count
runs the same jobs; the rate is jobs / wall time, with Ray's start-up (a local instance) timed
apart. The reference is one local worker measured in the same run, so the ratio says what more
workers buy on this machine.

    .venv/bin/python benchmarks/bench_grid.py                 # 24 jobs, 1 and 2 workers, both engines
    .venv/bin/python benchmarks/bench_grid.py --jobs 48 --workers 1 2 4
"""

from __future__ import annotations

import argparse
import os
import time

from terrapref.evaluation.runner import EXPERT, RunSpec, run_many
from terrapref.grid import Engine, start_ray

PROFILE = ("mud", "rock", "water", "non_traversable")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--jobs", type=int, default=24)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--engines", nargs="+", default=["local", "ray"])
    args = ap.parse_args()
    specs = [RunSpec(f"gen:{1000 + i}", 0, EXPERT, None, PROFILE) for i in range(args.jobs)]
    print(f"{args.jobs} jobs (the synthetic driver on gen:1000-gen:{999 + args.jobs}); {os.cpu_count()} cores")
    print("| engine | workers | start-up | wall (jobs) | jobs/s | ratio to 1 local worker |")
    print("|---|---|---|---|---|---|")
    reference = None
    for engine in args.engines:
        for workers in args.workers:
            startup = 0.0
            if engine == "ray":
                import ray

                t0 = time.perf_counter()
                start_ray(Engine("ray", workers))  # as run_grid would, timed apart
                ray.get([ray.remote(lambda: None).remote() for _ in range(workers)])  # workers started
                startup = time.perf_counter() - t0
            t0 = time.perf_counter()
            run_many(specs, engine=Engine(engine, workers))
            wall = time.perf_counter() - t0
            if engine == "ray":
                ray.shutdown()
            rate = args.jobs / wall
            if reference is None and engine == "local" and workers == 1:
                reference = rate
            ratio = f"{rate / reference:.2f}x" if reference else "-"
            print(f"| {engine} | {workers} | {startup:.1f} s | {wall:.1f} s | {rate:.2f} | {ratio} |", flush=True)


if __name__ == "__main__":
    main()
