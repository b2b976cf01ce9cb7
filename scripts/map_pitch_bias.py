"""The grade the planner's height layer reads ahead on a plane, under a camera whose pitch wanders.

Frames are taken every ``--step`` metres along a straight line over a level plane, the camera's
pitch off its mount wandering as the `field` preset's does (an Ornstein-Uhlenbeck process of
``--sigma`` degrees and ``--tau`` seconds at 10 frames a second; ``--tau 0``: each frame its own;
``--held D``: held at D degrees), and folded into a fresh ground map told the mount's attitude.
From the 100th frame on, every fifth, the map's grade along the heading is read 0-5 m ahead.
The true grade is 0 everywhere, so what is printed is the error (the lab book,
docs/lab/2026-12-06-frames-turned-back.md). About 2 s a run.

    python scripts/map_pitch_bias.py [--sigma 2] [--tau 0.3] [--held D] [--frames 600] [--seed 0]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationRenderer, SegmentationView
from terrapref.features import FeatureConfig, UtilityFeaturizer
from terrapref.groundmap.columns import TerrainColumns
from terrapref.groundmap.height import DepthImage
from terrapref.groundmap.map import GroundMap
from terrapref.scenario import FORMAT, parse_scenario
from terrapref.terrain import default_classes
from terrapref.vehicle import Pose, Vehicle
from terrapref.vehicle.ground import Attitude
from terrapref.world import rasterise

# A level plane 120 m long; a low plateau in one corner, far from the line, gives it relief (so
# that frames carry depth).
PLANE = {
    "format": FORMAT,
    "name": "plane",
    "world": {"size_m": [120.0, 30.0], "resolution_m": 0.05, "background": "grass"},
    "terrain": [],
    "path": {"waypoints": [[1.0, 15.0], [119.0, 15.0]]},
    "relief": [{"plateau": {"polygon": [[115, 0], [120, 0], [120, 2], [115, 2]], "height_m": 0.05, "edge_m": 0.5}}],
}
PERIOD_S = 0.1


def pitches(args: argparse.Namespace) -> np.ndarray:
    """The camera's pitch off its mount at each frame [rad]."""
    if args.held is not None:
        return np.full(args.frames, math.radians(args.held))
    rng = np.random.default_rng(args.seed)
    sigma = math.radians(args.sigma)
    rho = math.exp(-PERIOD_S / args.tau) if args.tau > 0 else 0.0
    out = np.empty(args.frames)
    d = rng.normal() * sigma
    for k in range(args.frames):
        d = rho * d + math.sqrt(1.0 - rho * rho) * sigma * rng.normal()
        out[k] = d
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sigma", type=float, default=2.0, help="the pitch's wander (std) [deg]")
    parser.add_argument("--tau", type=float, default=0.3, help="its correlation time [s] (0: each frame its own)")
    parser.add_argument("--held", type=float, default=None, help="hold the pitch at this many degrees instead")
    parser.add_argument("--frames", type=int, default=600)
    parser.add_argument("--step", type=float, default=0.14, help="metres between frames (1.4 m/s)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    classes = default_classes()
    world = rasterise(parse_scenario(PLANE, "plane.yaml"))
    camera = PinholeCamera()
    columns = UtilityFeaturizer(FeatureConfig(), camera).class_columns
    renderer = SegmentationRenderer(camera, world)
    gmap = GroundMap(camera, TerrainColumns.of(columns, len(classes.feature_names), classes))
    wander = pitches(args)
    reads: dict[int, list[float]] = {ahead: [] for ahead in range(5)}
    for k, off in enumerate(wander):
        x = 5.0 + args.step * k
        vehicle = Vehicle(Pose(x, 15.0, 0.0), ground=world)
        a = vehicle.attitude
        ids, depth = renderer.render_with_depth(vehicle.pose, Attitude(a.z_m, a.pitch_rad + off, a.roll_rad))
        gmap.update(SegmentationView.of(ids), vehicle.pose, DepthImage(depth, *renderer.placement(vehicle.pose, a)))
        if k < 100 or k % 5:
            continue
        for ahead in reads:
            points = np.array([[x + ahead + 0.5, 15.0 + side] for side in (-1.0, 0.0, 1.0)])
            gradient = gmap.gradient_at(points)
            known = np.isfinite(gradient[:, 0])
            reads[ahead].extend(np.degrees(np.arctan(gradient[known, 0])))
    print(f"the frames' pitch off the mount: {np.degrees(wander.mean()):+.2f} deg mean, {np.degrees(wander.std()):.2f} deg std")
    for ahead, grades in reads.items():
        g = np.array(grades)
        if len(g):
            print(f"{ahead}-{ahead + 1} m ahead: grade read {g.mean():+.2f} deg (mean), {g.std():.2f} deg (std), {len(g)} reads")


if __name__ == "__main__":
    main()
