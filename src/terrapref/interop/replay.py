"""Open-loop replay: the runtime over a held-out log, against what the operator did.

For every frame of the log the model decides from the same label image, stamp and pose as the
operator had, and the robot's speed as a node reads it from odometry, and the replay counts how often its trajectory is the operator's (top-1), how
often the operator's is among the three C finds most probable (top-3: C's alone, since the
planner's rules choose one trajectory and rank none), how far its way bends from the operator's
(mean |w| error) and how far its speed is from the operator's (mean |v| error), over all frames
and over the frames where terrain lies on some trajectory (where the preference matters). The
check a team makes before putting a model on the robot.

The two errors keep steering and speed apart. The |w| error compares curvatures, each as the yaw
rate it gives at the control set's speed, w x v_set / v (the operator's command brought to v_set
as the dataset labels it; the model's command likewise, or where it stops the chosen trajectory's
w), so that the right way driven at another speed counts no |w| error. The |v| error compares the
speed the model commands (0 where it stops; the control set's speed for a model without a speed
rule) with the operator's; C alone picks no speed, so its rows have none (null).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.dataset import at_set_speed  # the dataset's own: the replay compares ways as training labels them
from terrapref.demos.recording import Recording
from terrapref.errors import UserError
from terrapref.fileio import atomic_path, write_bytes_atomic
from terrapref.interop.runtime import SPEED_WINDOW_S, DepthFrame, PlannerRuntime, RobotSettings, odometry_speed_mps
from terrapref.planner.model import Model
from terrapref.vehicle import Pose


def _rates(hit1: np.ndarray, hit3: np.ndarray | None, werr: np.ndarray, verr: np.ndarray | None) -> dict:
    """Top-1, top-3 (None where there is no ranking), mean |w| error [rad/s] and mean |v| error
    [m/s] (None where no speed is chosen) over the frames given (each (n,))."""
    n = int(len(hit1))
    return {
        "frames": n,
        "top1": float(hit1.mean()) if n else None,
        "top3": float(hit3.mean()) if n and hit3 is not None else None,
        "mean_abs_w_error_rps": float(werr.mean()) if n else None,
        "mean_abs_v_error_mps": float(verr.mean()) if n and verr is not None else None,
    }


def summary_lines(result: dict) -> list[str]:
    """What a replay found, a line per set of frames (as ``terrapref replay`` prints it)."""
    out = []
    for name, key in (
        ("planner, all frames", "overall"),
        ("planner, terrain", "terrain_in_view"),
        ("C alone, all", "classifier_overall"),
        ("C alone, terrain", "classifier_terrain_in_view"),
    ):
        r = result[key]
        if not r["frames"]:
            out.append(f"{name:20s} no frames")
            continue
        top3 = f", top-3 {r['top3']:.1%}" if r["top3"] is not None else ""
        v = f", mean |v| error {r['mean_abs_v_error_mps']:.3f} m/s" if r["mean_abs_v_error_mps"] is not None else ""
        out.append(
            f"{name:20s} top-1 {r['top1']:.1%}{top3}, mean |w| error {r['mean_abs_w_error_rps']:.3f} rad/s{v} over {r['frames']} frames"
        )
    return out


def frame_speeds(times: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """The robot's speed at each frame [m/s] as a node reads it from odometry
    (terrapref.interop.runtime.odometry_speed_mps): its forward motion over the
    :data:`SPEED_WINDOW_S` before the frame, the poses between frames interpolated; NaN where the
    log does not reach that far back. ``times`` (F,) [s], ``poses`` (F, 3)."""
    times = np.asarray(times, dtype=float)
    back = times - SPEED_WINDOW_S
    yaw = np.unwrap(poses[:, 2])
    before = np.stack([np.interp(back, times, poses[:, 0]), np.interp(back, times, poses[:, 1]), np.interp(back, times, yaw)], axis=1)
    out = np.array([odometry_speed_mps(Pose(*poses[i]), Pose(*before[i])) for i in range(len(times))])
    out[back < times[0] - 1e-9] = np.nan
    return out


def replay(model: Model, rec: Recording, progress=None, robot: RobotSettings | None = None) -> dict:
    """Decide on every frame of ``rec`` with ``model``; the metrics and the per-frame series.

    A frame that carries a depth image is decided on with it and the body's attitude the
    recording holds (level where it holds none), as a robot's node would hand them over; the
    runtime has the ``robot``'s settings (its stop rule, limits and rules' settings, as its robot
    file gives them to a node; None: the defaults). A model trained for another camera than the
    log's is refused (UserError).
    """
    runtime = PlannerRuntime(model, camera=CameraConfig.from_dict(rec.meta["camera"]), robot=robot)
    path = np.asarray(rec.meta.get("path") or rec.scenario["path"]["waypoints"], dtype=float)
    runtime.set_path(path)
    control = model.features.preference.control
    w_grid = np.asarray(control.w_rps)
    chosen, commands, c_best, top3, terrain = _decisions(runtime, rec, model.features.n_terrain, progress)
    w_operator = at_set_speed(rec.commands, control.v_mps).astype(float)
    v_operator, v_model = rec.commands[:, 0].astype(float), commands[:, 0]
    w_model = np.where(v_model > 0, at_set_speed(commands, control.v_mps).astype(float), w_grid[chosen])  # a stop keeps its way's w
    hit1 = chosen == rec.labels
    werr = np.abs(w_model - w_operator)
    verr = np.abs(v_model - v_operator)
    c_hit1 = c_best == rec.labels
    c_werr = np.abs(w_grid[c_best] - w_operator)
    return {
        # The planner's decision rules choose one trajectory and rank none, so only C, whose F_t
        # ranks all m, has a top-3 (null for the planner: it would be C's own again).
        "overall": _rates(hit1, None, werr, verr),
        "terrain_in_view": _rates(hit1[terrain], None, werr[terrain], verr[terrain]),
        # C's own argmax, as training's accuracy measures it; the planner's rules choose by more
        # than F_t. C picks no speed: the speed rule sets it along the way the planner chose.
        "classifier_overall": _rates(c_hit1, top3, c_werr, None),
        "classifier_terrain_in_view": _rates(c_hit1[terrain], top3[terrain], c_werr[terrain], None),
        "series": {
            "t": rec.times.tolist(),
            "w_operator": w_operator.tolist(),  # at the control set's speed, as w_model
            "w_model": w_model.tolist(),
            "v_operator": v_operator.tolist(),
            "v_model": v_model.tolist(),
            "terrain": terrain.tolist(),
            "top1": hit1.tolist(),
            "xy": rec.poses[:, :2].tolist(),
        },
    }


def _decisions(runtime: PlannerRuntime, rec: Recording, n_terrain: int, progress=None) -> tuple[np.ndarray, ...]:
    """The runtime's decision on each frame of ``rec``: the trajectory chosen (F,), the command
    (F, 2: v [m/s], w [rad/s]), C's argmax (F,), whether the operator's trajectory is among C's
    three likeliest (F,) and whether terrain lies on some trajectory (F,)."""
    chosen = np.empty(len(rec), dtype=np.int64)
    commands = np.empty((len(rec), 2))
    c_best = np.empty(len(rec), dtype=np.int64)
    top3 = np.empty(len(rec), dtype=bool)
    terrain = np.empty(len(rec), dtype=bool)
    speeds = frame_speeds(rec.times, rec.poses)
    for i in range(len(rec)):
        depth = rec.depth(i)
        seen = DepthFrame(depth, rec.attitude(i)) if depth is not None else None
        speed = None if np.isnan(speeds[i]) else float(speeds[i])
        try:  # never None: read_recording refuses times that do not grow
            d = runtime.decide(rec.image(i), float(rec.times[i]), tuple(rec.poses[i]), speed, depth=seen)
        except ValueError as exc:  # a frame the robot's runtime refuses (its odometry past the robot file's limits, say)
            raise UserError(str(rec.path), f"frame {i}: {exc}") from None
        chosen[i] = d.index
        commands[i] = d.command
        c_best[i] = int(np.argmax(d.probs))
        top3[i] = rec.labels[i] in np.argsort(d.probs)[-3:]
        terrain[i] = bool((d.U[:, :n_terrain] > 0).any())
        if progress is not None:
            progress(i + 1, len(rec))
    return chosen, commands, c_best, top3, terrain


def write_replay(result: dict, out: Path, title: str) -> tuple[Path, Path]:
    """``replay.json`` (metrics and series) and ``replay.png`` (the drive at a glance)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    s = result["series"]
    t, terrain, hit = np.asarray(s["t"]), np.asarray(s["terrain"]), np.asarray(s["top1"], dtype=float)
    fig = plt.figure(figsize=(14, 10), constrained_layout=True)
    grid = fig.add_gridspec(4, 1, height_ratios=[1.2, 0.8, 1, 1.1])
    ax = fig.add_subplot(grid[0, 0])
    for k in np.flatnonzero(terrain):
        ax.axvspan(t[k] - 0.05, t[k] + 0.05, color="#f3e2c7", lw=0)
    ax.plot(t, s["w_operator"], color="black", lw=1.2, label="operator")
    ax.plot(t, s["w_model"], color="tab:red", lw=0.9, alpha=0.8, label="planner")
    ax.set_ylabel("w at the set's speed [rad/s]")
    ax.set_title("the way along the drive: yaw rate at the control set's speed, of the same curvature (shaded: terrain on some trajectory)")
    ax.legend(loc="upper right")
    ax_v = fig.add_subplot(grid[1, 0], sharex=ax)
    ax_v.plot(t, s["v_operator"], color="black", lw=1.2, label="operator")
    ax_v.plot(t, s["v_model"], color="tab:red", lw=0.9, alpha=0.8, label="planner")
    ax_v.set_ylim(bottom=0.0)
    ax_v.set_ylabel("speed v [m/s]")
    ax2 = fig.add_subplot(grid[2, 0], sharex=ax)
    window = max(1, min(len(hit), 50))
    rolling = np.convolve(hit, np.ones(window) / window, mode="same")
    ax2.plot(t, rolling, color="tab:blue")
    ax2.set_ylim(0, 1.02)
    ax2.set_xlabel("time [s]")
    ax2.set_ylabel(f"top-1 agreement ({window / 10:g} s window)")
    o, v = result["overall"], result["terrain_in_view"]
    c = result["classifier_overall"]
    ax2.set_title(
        f"planner, all frames: {_figures(o)}\nplanner, terrain in view: {_figures(v)}\nC alone (argmax F_t), all frames: {_figures(c)}",
        fontsize=9,
    )
    ax3 = fig.add_subplot(grid[3, 0])
    xy = np.asarray(s["xy"])
    ax3.scatter(xy[:, 0], xy[:, 1], c=np.where(hit > 0, "tab:green", "tab:red"), s=4)
    ax3.set_aspect("equal")
    ax3.set_title("driven path: the planner makes the operator's choice (green) or not (red)")
    ax3.set_xlabel("x [m]")
    ax3.set_ylabel("y [m]")
    fig.suptitle(title)
    png = out / "replay.png"
    try:
        with atomic_path(png) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    js = write_bytes_atomic(out / "replay.json", json.dumps(result, indent=1).encode())
    return js, png


def _figures(r: dict) -> str:
    """One set of frames' figures, short, for the figure's title."""
    if r["top1"] is None:
        return "n/a"
    top3 = f", top-3 {r['top3']:.0%}" if r["top3"] is not None else ""
    v = f", |v| error {r['mean_abs_v_error_mps']:.3f} m/s" if r["mean_abs_v_error_mps"] is not None else ""
    return f"top-1 {r['top1']:.0%}{top3}, |w| error {r['mean_abs_w_error_rps']:.3f} rad/s{v} ({r['frames']} frames)"
