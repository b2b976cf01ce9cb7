"""Decision time of a model file in closed loop: the planner drives a course, and each decision is timed.

On a course with relief (``genrelief:2000``) each frame comes with its depth image, rendered
before the decision is timed, as a robot's camera gives it; the decision then gathers heights
and blocks ground past the robot's limits (terrapref.groundmap.height).

For models of any class table (``--classes FILE`` reads the course with that table), beside the
reference the other benchmarks use, measured in the same run:

    OMP_NUM_THREADS=1 taskset -c 0 .venv/bin/python benchmarks/bench_model.py me.safetensors gen:2000 \\
        --classes examples/classes/rellis3d.yaml

The default decision on relief beside the flat one, in turn (``scripts/bench.sh`` makes both
models, each from one drive):

    OMP_NUM_THREADS=1 taskset -c 0 .venv/bin/python benchmarks/bench_model.py relief.safetensors genrelief:2000 \\
        --beside flat.safetensors gen:2000
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from reference import reference_ms  # benchmarks/reference.py (the script's folder is on sys.path)

from terrapref.learning.model_file import load_model
from terrapref.planner import Planner, PlannerDriver
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation, run_episode
from terrapref.terrain import load_classes


def decision_times(model_path: str, scenario: str, classes_file: str | None) -> np.ndarray:
    """Every decision's wall time [s] of one closed-loop run (seed 0) of the model on the course."""
    model = load_model(model_path)
    sim = Simulation(resolve_scenario(scenario, load_classes(classes_file) if classes_file else None))
    driver = PlannerDriver(Planner(model))
    times: list[float] = []
    act = driver.act

    def timed(frame):
        if frame.view.carries_depth:  # on relief: the frame and its depth rendered first, as a robot's come
            frame.view.depth  # noqa: B018
        t0 = time.perf_counter()
        command = act(frame)
        times.append(time.perf_counter() - t0)
        return command

    driver.act = timed
    run_episode(sim, driver, np.random.default_rng(0))
    return np.array(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model")
    parser.add_argument("scenario")
    parser.add_argument("--classes", help="the class table the course is read with (a terrapref-classes/1 file)")
    parser.add_argument(
        "--beside",
        nargs=2,
        metavar=("MODEL", "SCENARIO"),
        help="a second decision timed in turn with the first (e.g. a flat model on gen:2000 beside a relief one): "
        "three runs of each, and the ratio of their medians run by run (--classes reads both courses)",
    )
    args = parser.parse_args()
    decision_times(args.model, args.scenario, args.classes)  # compiled loops and caches warmed
    if args.beside is not None:
        decision_times(*args.beside, args.classes)
        _in_turn((args.model, args.scenario), tuple(args.beside), args.classes)
        return
    t = decision_times(args.model, args.scenario, args.classes)
    ref = reference_ms()
    print(f"reference: naive NumPy render (reference.py)  {ref:.2f} ms")
    _report(args.model, args.scenario, t, ref)


def _report(model: str, scenario: str, t: np.ndarray, ref: float) -> None:
    columns = len(load_model(model).features.feature_classes)
    print(
        f"decision of {model} ({columns} terrain columns) on {scenario}: median {np.median(t) * 1e6:.1f} us, "
        f"p90 {np.percentile(t, 90) * 1e6:.1f} us over {len(t)} decisions; median / reference {np.median(t) * 1e3 / ref:.4f}"
    )


def _in_turn(first: tuple[str, str], second: tuple[str, str], classes: str | None, runs: int = 3) -> None:
    """``runs`` runs of each decision in turn, each beside a reference, and the ratio of their
    medians run by run: on a shared machine the two move together, and the ratio holds better
    than either."""
    ratios = []
    for run in range(runs):
        ref = reference_ms()
        print(f"run {run + 1}: reference: naive NumPy render (reference.py)  {ref:.2f} ms")
        a, b = decision_times(*first, classes), decision_times(*second, classes)
        _report(*first, a, ref)
        _report(*second, b, ref)
        ratios.append(float(np.median(a) / np.median(b)))
        print(f"run {run + 1}: the first's median over the second's: {ratios[-1]:.2f}")
    middle, low, high = sorted(ratios)[runs // 2], min(ratios), max(ratios)
    print(f"the first decision over the second, the middle of {runs} runs: {middle:.2f} ({low:.2f}-{high:.2f})")


if __name__ == "__main__":
    main()
