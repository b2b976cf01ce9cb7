"""What the trajectories show at the moment the synthetic driver commits to a detour.

The driver drives each generated course. At every frame where it leaves the path (its held
offset turns from zero to non-zero), the zone it enters next is found, and the terrain shares
of the m trajectories are read from that frame's segmentation image, exactly as the planner
would compute them. For a pair or a triple, the script counts whether the best class (under the
driver's profile) and the other candidate are on some trajectory at that moment. A decision
taken while the other candidate is out of reach cannot be learned from U alone.

    python scripts/commit_visibility.py [--courses 16] [--first 1000] [--min-points 2]
"""

from __future__ import annotations

import argparse
from collections import Counter

import numpy as np

from terrapref.camera import CameraConfig, PinholeCamera
from terrapref.demos.expert import ExpertConfig, ExpertDriver
from terrapref.features import FeatureConfig
from terrapref.features.utility import UtilityFeaturizer
from terrapref.scenario import resolve_scenario
from terrapref.scenario.generate import zone_kind
from terrapref.sim import SimConfig, Simulation
from terrapref.world import rasterise

ENTRY_WINDOW_FRAMES = 120  # a commit belongs to the zone entered within the next 12 s


def commits(course: str, features: FeatureConfig, profile: tuple[str, ...]) -> list[tuple[str, list[str], dict[str, int]]]:
    """Per commit: (zone kind, the zone's classes left to right, the most points any one trajectory has on each class)."""
    scenario = resolve_scenario(course)
    world = rasterise(scenario)
    camera = CameraConfig()
    featurizer = UtilityFeaturizer(features, PinholeCamera(camera), scenario.classes)
    sim = Simulation(scenario, camera, SimConfig(), world=world)
    driver = ExpertDriver(ExpertConfig(profile=profile), world=world)
    frame = sim.reset()
    driver.reset(scenario, np.random.default_rng(0))
    names = list(features.feature_classes)
    poses, shares = [], {}  # shares only at the commit frames: frame index -> (K,)
    held = 0.0
    while not sim.done:
        command = driver.act(frame)
        if held == 0.0 and driver.offset != 0.0:
            shares[len(poses)] = featurizer.terrain(frame.view).max(axis=0)
        poses.append(frame.pose[:2])
        held = driver.offset
        frame = sim.step(command)
    poses_arr = np.array(poses)
    inside = {z.id: z.shape.contains(poses_arr) for z in scenario.zones}
    n = features.preference.n_steps
    out, used = [], set()
    for i in sorted(shares):
        ahead = slice(i, i + ENTRY_WINDOW_FRAMES)
        entered = [(int(np.argmax(inside[z.id][ahead])), z) for z in scenario.zones if inside[z.id][ahead].any() and z.id not in used]
        if not entered:
            continue
        _, zone = min(entered, key=lambda e: e[0])
        used.add(zone.id)
        label = zone.label or ""
        parts = [p.strip() for p in label.split("|")] if "|" in label else [label.removeprefix("lone ").strip()]
        out.append((zone_kind(label), parts, {c: int(round(shares[i][names.index(c)] * n)) for c in names}))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--courses", type=int, default=16, help="generated courses gen:FIRST ... (default 16)")
    parser.add_argument("--first", type=int, default=1000, help="seed of the first generated course (default 1000)")
    parser.add_argument("--min-points", type=int, default=2, help="points of a trajectory on a class for it to count as seen (default 2)")
    args = parser.parse_args()
    if args.courses < 1 or args.first < 0 or args.min_points < 1:
        parser.error("--courses and --min-points must be >= 1, --first >= 0")
    features = FeatureConfig()
    profile = ExpertConfig().profile
    table: Counter = Counter()
    for k in range(args.courses):
        course = f"gen:{args.first + k}"
        for kind, parts, points in commits(course, features, profile):
            if kind == "lone":
                continue
            best = min(parts, key=profile.index)
            if kind == "pair":
                row, other = "pair", next(p for p in parts if p != best)
            elif parts[1] == best:  # the alternative is the better side
                row, other = "triple, best in the middle", min((parts[0], parts[2]), key=profile.index)
            else:  # the alternative is the side across from the best one
                row, other = "triple, best on a side", parts[2] if parts[0] == best else parts[0]
            seen_best, seen_other = points[best] >= args.min_points, points[other] >= args.min_points
            table[(row, "zones")] += 1
            table[
                (
                    row,
                    {(True, True): "both", (True, False): "best only", (False, True): "other only", (False, False): "neither"}[
                        (seen_best, seen_other)
                    ],
                )
            ] += 1
        print(f"{course}: done", flush=True)
    print(f"\nclasses on some trajectory (>= {args.min_points} of {features.preference.n_steps} points) when the driver commits")
    print(f"{'zone kind':30s} {'zones':>6s} {'both':>6s} {'best only':>10s} {'other only':>11s} {'neither':>8s}")
    for row in ("pair", "triple, best on a side", "triple, best in the middle"):
        if table[(row, "zones")]:
            print(
                f"{row:30s} {table[(row, 'zones')]:6d} {table[(row, 'both')]:6d} {table[(row, 'best only')]:10d} {table[(row, 'other only')]:11d} {table[(row, 'neither')]:8d}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
