"""Check that demonstrations identify the preference: fit the linear utility model and print it.

The model scores each trajectory i with w . U_i + b_i (one weight per utility, a bias per
trajectory) and takes a softmax over the m trajectories (terrapref.learning.linear). Weights in the profile's order (all negative, the best class
nearest zero) and a positive distance weight mean the data can teach the preference.

    python scripts/fit_linear_utility.py REC_DIR... [--n-steps 30 --dt 0.2 --distance-mode lookahead]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from terrapref.dataset import build_dataset
from terrapref.demos.recording import read_recording
from terrapref.features import FeatureConfig
from terrapref.learning.linear import fit_linear_utility


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recordings", nargs="+")
    parser.add_argument("--n-steps", type=int, default=30)
    parser.add_argument("--dt", type=float, default=0.2)
    parser.add_argument("--distance-mode", default="progress", choices=["progress", "window", "paper"])
    args = parser.parse_args()
    fc = FeatureConfig(distance_mode=args.distance_mode)
    fc = replace(fc, preference=replace(fc.preference, n_steps=args.n_steps, dt_s=args.dt))
    ds = build_dataset([read_recording(r) for r in args.recordings], fc)
    in_view = (ds.U[:, :, :-1].sum(axis=2) > 0).any(axis=1)
    lin = fit_linear_utility(ds.U, ds.labels)
    w, acc = lin.w, float((lin.logits(ds.U.astype(np.float64)).argmax(axis=1) == ds.labels).mean())
    print(
        f"n={args.n_steps} dt={args.dt} distance={args.distance_mode}: {len(ds)} frames, terrain on some trajectory in {in_view.mean():.0%}"
    )
    print("weights  " + "  ".join(f"{name} {v:+.2f}" for name, v in zip(fc.column_names, w)) + f"   accuracy {acc:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
