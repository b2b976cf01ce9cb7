"""Check that demonstrations identify the preference: fit the linear utility model and print it.

The model scores each trajectory i with w . U_i + b_i (one weight per utility, a bias per
trajectory) and takes a softmax over the m trajectories; fitted by full-batch gradient descent
with Adam on the cross entropy. Weights in the profile's order (all negative, the best class
nearest zero) and a positive distance weight mean the data can teach the preference.

    python scripts/fit_linear_utility.py REC_DIR... [--n-steps 30 --dt 0.2 --distance-mode lookahead]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from terrapref.demos.dataset import build_dataset
from terrapref.demos.recording import read_recording
from terrapref.features import FeatureConfig


def fit(U: np.ndarray, y: np.ndarray, steps: int = 1500, lr: float = 0.05) -> tuple[np.ndarray, np.ndarray, float]:
    n, m, k = U.shape
    params = np.zeros(k + m)
    mom, vel = np.zeros_like(params), np.zeros_like(params)
    onehot = np.eye(m)[y]
    for t in range(1, steps + 1):
        logits = U @ params[:k] + params[k:]
        p = np.exp(logits - logits.max(axis=1, keepdims=True))
        p /= p.sum(axis=1, keepdims=True)
        g = p - onehot  # d loss / d logits, (n, m)
        grad = np.concatenate([np.einsum("nm,nmk->k", g, U), g.sum(axis=0)]) / n
        mom = 0.9 * mom + 0.1 * grad
        vel = 0.999 * vel + 0.001 * grad**2
        params -= lr * (mom / (1 - 0.9**t)) / (np.sqrt(vel / (1 - 0.999**t)) + 1e-8)
    logits = U @ params[:k] + params[k:]
    return params[:k], params[k:], float((logits.argmax(axis=1) == y).mean())


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recordings", nargs="+")
    parser.add_argument("--n-steps", type=int, default=30)
    parser.add_argument("--dt", type=float, default=0.2)
    parser.add_argument("--distance-mode", default="lookahead", choices=["lookahead", "window", "paper"])
    args = parser.parse_args()
    fc = FeatureConfig(distance_mode=args.distance_mode)
    fc = replace(fc, preference=replace(fc.preference, n_steps=args.n_steps, dt_s=args.dt))
    ds = build_dataset([read_recording(r) for r in args.recordings], fc)
    in_view = (ds.U[:, :, :-1].sum(axis=2) > 0).any(axis=1)
    w, _, acc = fit(ds.U.astype(np.float64), ds.labels)
    print(f"n={args.n_steps} dt={args.dt} distance={args.distance_mode}: {len(ds)} frames, terrain on some trajectory in {in_view.mean():.0%}")
    print("weights  " + "  ".join(f"{name} {v:+.2f}" for name, v in zip(fc.column_names, w)) + f"   accuracy {acc:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
