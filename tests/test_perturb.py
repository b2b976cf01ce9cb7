"""The robustness study's perturbations: corrupted segmentation, pose noise, dropped and delayed
frames, and one perturbed closed-loop run."""

from __future__ import annotations

import numpy as np
import pytest

from terrapref.camera import SegmentationView
from terrapref.evaluation.perturb import FrameNoise, NoisyView, Perturbation, PerturbedDriver, corrupt_image
from terrapref.evaluation.runner import PURE_PURSUIT, RunSpec, run_one
from terrapref.sim.loop import Frame
from terrapref.vehicle import Command, Pose

H, W = 120, 160
HELD = Command(1.0, 0.3)
WAYPOINTS = np.array([[0.0, 0.0], [10.0, 0.0]])
PROFILE = ("mud", "rock", "water", "non_traversable")


def _image(value: int = 0) -> np.ndarray:
    return np.full((H, W), value, dtype=np.uint8)


def _frame(i: int, image: np.ndarray | None = None) -> Frame:
    img = _image() if image is None else image
    return Frame(index=i, time_s=0.1 * i, view=SegmentationView.of(img), pose=Pose(0.5 * i, 0.1 * i, 0.01 * i), waypoints=WAYPOINTS)


class FakeDriver:
    """Records what it is handed and always answers the same command."""

    def __init__(self) -> None:
        self.frames: list[Frame] = []
        self.resets = 0

    def reset(self, scenario, rng) -> None:
        self.resets += 1
        self.frames = []

    def act(self, frame: Frame) -> Command:
        self.frames.append(frame)
        return HELD


def _driver(p: Perturbation, seed: int = 0) -> tuple[PerturbedDriver, FakeDriver]:
    inner = FakeDriver()
    driver = PerturbedDriver(inner, p, camera_rate_hz=10.0)
    driver.reset(None, np.random.default_rng(seed))
    assert inner.resets == 1
    return driver, inner


# --- Perturbation --------------------------------------------------------------------------------


def test_default_is_inactive():
    assert not Perturbation().active
    for kw in ({"flip_rate": 0.1}, {"blobs": 1.0}, {"pose_noise_m": 0.1}, {"pose_noise_deg": 1.0}, {"drop_rate": 0.1}, {"delay_frames": 1}):
        assert Perturbation(**kw).active, kw
    assert not Perturbation(hold_s=2.0, n_classes=3).active  # settings that perturb nothing alone


@pytest.mark.parametrize("kw", [{"flip_rate": 2.0}, {"flip_rate": -0.1}, {"drop_rate": 1.5}, {"blobs": -1.0},
                                {"delay_frames": -1}, {"pose_noise_m": -0.1}, {"pose_noise_deg": -1.0}, {"hold_s": -0.5}])
def test_invalid_perturbation_is_refused(kw: dict):
    with pytest.raises(ValueError):
        Perturbation(**kw)


def test_to_dict():
    d = Perturbation(flip_rate=0.1, delay_frames=2).to_dict()
    assert d["flip_rate"] == 0.1 and d["delay_frames"] == 2 and d["drop_rate"] == 0.0
    assert Perturbation(**d) == Perturbation(flip_rate=0.1, delay_frames=2)


# --- corrupt_image ---------------------------------------------------------------------------------


def test_zero_perturbation_returns_the_same_object():
    image = np.random.default_rng(0).integers(0, 5, size=(H, W), dtype=np.uint8)
    assert corrupt_image(image, Perturbation(), np.random.default_rng(0)) is image
    assert corrupt_image(image, Perturbation(pose_noise_m=1.0, drop_rate=0.5), np.random.default_rng(0)) is image


@pytest.mark.parametrize("p", [Perturbation(flip_rate=0.5), Perturbation(blobs=3.0), Perturbation(flip_rate=0.2, blobs=2.0)])
def test_corrupt_image_leaves_its_input_alone(p: Perturbation):
    image = np.random.default_rng(1).integers(0, 5, size=(H, W), dtype=np.uint8)
    before = image.copy()
    out = corrupt_image(image, p, np.random.default_rng(2))
    np.testing.assert_array_equal(image, before)
    assert out is not image and not np.shares_memory(out, image)
    assert out.shape == image.shape and out.dtype == image.dtype
    assert not np.array_equal(out, image)


def test_flip_rate_changes_the_expected_share():
    image = _image(0)
    out = corrupt_image(image, Perturbation(flip_rate=0.5), np.random.default_rng(3))
    changed = float(np.mean(out != image))
    # Half the pixels are redrawn; a redraw lands on the same class 1 time in 5: about 0.4.
    assert 0.3 < changed < 0.5
    assert set(np.unique(out)) <= set(range(5))
    # Every class is drawn about equally often among the redrawn pixels.
    counts = np.bincount(out[out != image], minlength=5)[1:]
    assert counts.min() > 0.8 * counts.mean()


def test_flip_rate_uses_n_classes():
    out = corrupt_image(_image(0), Perturbation(flip_rate=1.0, n_classes=2), np.random.default_rng(4))
    assert set(np.unique(out)) == {0, 1}
    assert 0.4 < float(np.mean(out == 1)) < 0.6


def test_corruption_is_reproducible():
    image = np.random.default_rng(5).integers(0, 5, size=(H, W), dtype=np.uint8)
    p = Perturbation(flip_rate=0.3, blobs=2.0)
    a = corrupt_image(image, p, np.random.default_rng(42))
    b = corrupt_image(image, p, np.random.default_rng(42))
    c = corrupt_image(image, p, np.random.default_rng(43))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_blobs_paint_the_ground_part_of_the_view():
    """Blob centres are in the lower half; a blob reaches at most its radius above its centre."""
    r_max = 12
    p = Perturbation(blobs=4.0, blob_radius_px=(4, r_max))
    rng = np.random.default_rng(6)
    painted_rows = []
    for _ in range(30):
        image = _image(255)  # no blob colour equals the background: every painted pixel shows
        out = corrupt_image(image, p, rng)
        rows = np.nonzero((out != image).any(axis=1))[0]
        painted_rows.extend(rows.tolist())
        assert set(np.unique(out)) <= set(range(5)) | {255}
    assert painted_rows  # 30 frames with 4 blobs expected each: something was painted
    assert min(painted_rows) >= H // 2 - r_max
    rows = np.array(painted_rows)
    assert np.mean(rows >= H // 2) > 0.8  # nearly all of it in the lower half
    assert rows.max() >= H * 3 // 4  # and not only near the middle


def test_blob_is_one_class_and_a_filled_region():
    p = Perturbation(blobs=1.0, blob_radius_px=(10, 10))
    rng = np.random.default_rng(7)
    seen = 0
    for _ in range(20):
        image = _image(255)
        out = corrupt_image(image, p, rng)
        changed = out != image
        if not changed.any():
            continue
        values = np.unique(out[changed])
        if len(values) == 1:  # a single blob (two could overlap with different classes)
            seen += 1
            ys, xs = np.nonzero(changed)
            assert xs.max() - xs.min() <= 20 and ys.max() - ys.min() <= 20
            assert changed.sum() >= 3.14 * 10 * 4 * 0.7 or xs.min() == 0 or xs.max() == W - 1 or ys.max() == H - 1
    assert seen > 3


# --- noise applied to the pixels read -------------------------------------------------------------


def _rendered_view(pose: Pose = Pose(8.0, 10.0, 0.2)) -> SegmentationView:
    from terrapref.camera import PinholeCamera, SegmentationRenderer
    from terrapref.scenario import resolve_scenario
    from terrapref.world import rasterise

    renderer = SegmentationRenderer(PinholeCamera(), rasterise(resolve_scenario("demo_course")))
    return SegmentationView(renderer, pose)


def test_a_noisy_view_gives_its_pixels_the_whole_frames_values_in_any_order():
    p = Perturbation(flip_rate=0.3, blobs=3.0)
    rng = np.random.default_rng(8)
    for _ in range(5):
        state = rng.bit_generator.state
        lazy = NoisyView(_rendered_view(), FrameNoise.draw(p, rng, (480, 640)))
        rng.bit_generator.state = state
        whole = NoisyView(_rendered_view(), FrameNoise.draw(p, rng, (480, 640)))
        idx = rng.integers(0, 480 * 640, 3000)
        first = lazy.pixels(idx)  # only these pixels: the frame is not rendered
        assert not lazy.rendered
        np.testing.assert_array_equal(first, whole.image.reshape(-1)[idx])
        np.testing.assert_array_equal(lazy.pixels(idx[::-1]), first[::-1])
        np.testing.assert_array_equal(lazy.image, whole.image)
        clean = _rendered_view().image
        changed = float(np.mean(whole.image != clean))
        assert 0.2 < changed < 0.6  # 30% redrawn (a fifth to the same class) and the blobs


def test_blobs_are_the_ellipses_drawn():
    """Each blob paints ((y - cy) / ry)^2 + ((x - cx) / rx)^2 <= 1, a later blob over an earlier one."""
    noise = FrameNoise(0, 0.0, 5, np.array([[60.0, 50.0, 10.0, 20.0, 3.0], [65.0, 60.0, 5.0, 5.0, 1.0]]))
    out = noise.apply(_image(0), np.arange(H * W), W).reshape(H, W)
    yy, xx = np.mgrid[0:H, 0:W]
    want = np.zeros((H, W), np.uint8)
    for cy, cx, ry, rx, cls in noise.blobs:
        want[((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 <= 1.0] = cls
    np.testing.assert_array_equal(out, want)


# --- PerturbedDriver -----------------------------------------------------------------------------


def test_no_perturbation_passes_frames_through():
    driver, inner = _driver(Perturbation())
    frames = [_frame(i) for i in range(5)]
    assert [driver.act(f) for f in frames] == [HELD] * 5
    assert [f.index for f in inner.frames] == list(range(5))
    for a, b in zip(inner.frames, frames):
        assert a.image is b.image and a.pose == b.pose
    assert driver.stops == 0


def test_all_frames_dropped_from_the_start_stops_at_once():
    driver, inner = _driver(Perturbation(drop_rate=1.0))
    out = [driver.act(_frame(i)) for i in range(8)]
    assert out == [Command(0.0, 0.0)] * 8  # no command yet to hold
    assert inner.frames == [] and driver.stops == 8


def test_dropped_frames_hold_then_stop():
    driver, inner = _driver(Perturbation())
    for i in range(3):
        assert driver.act(_frame(i)) == HELD
    driver.p = Perturbation(drop_rate=1.0)  # from now on no frame arrives
    out = [driver.act(_frame(i)) for i in range(3, 13)]
    # hold_s = 0.5 s at 10 Hz: the last command for 5 frames, then stop.
    assert out[:5] == [HELD] * 5
    assert out[5:] == [Command(0.0, 0.0)] * 5
    assert driver.stops == 5
    assert len(inner.frames) == 3
    # Frames return: the inner driver drives again and the blind time resets.
    driver.p = Perturbation()
    assert driver.act(_frame(13)) == HELD
    assert inner.frames[-1].index == 13
    driver.p = Perturbation(drop_rate=1.0)
    assert [driver.act(_frame(i)) for i in range(14, 20)] == [HELD] * 5 + [Command(0.0, 0.0)]
    assert driver.stops == 6


def test_hold_s_sets_the_hold():
    driver, _ = _driver(Perturbation())
    driver.act(_frame(0))
    driver.p = Perturbation(drop_rate=1.0, hold_s=0.2)
    assert [driver.act(_frame(i)) for i in range(1, 5)] == [HELD, HELD, Command(0.0, 0.0), Command(0.0, 0.0)]


def test_partial_drop_rate():
    driver, inner = _driver(Perturbation(drop_rate=0.3, hold_s=10.0))
    n = 400
    out = [driver.act(_frame(i)) for i in range(n)]
    share = 1 - len(inner.frames) / n
    assert 0.2 < share < 0.4
    assert driver.stops <= 10  # only before the first frame arrives (hold is long)
    assert out[-1] == HELD
    indices = [f.index for f in inner.frames]
    assert indices == sorted(indices) and len(set(indices)) == len(indices)


def test_drops_are_reproducible_per_seed():
    seen = []
    for seed in (0, 0, 1):
        driver, inner = _driver(Perturbation(drop_rate=0.5), seed=seed)
        for i in range(60):
            driver.act(_frame(i))
        seen.append([f.index for f in inner.frames])
    assert seen[0] == seen[1] and seen[0] != seen[2]


def test_delayed_frames():
    driver, inner = _driver(Perturbation(delay_frames=2))
    out = [driver.act(_frame(k)) for k in range(10)]
    assert out[:2] == [Command(0.0, 0.0)] * 2
    assert out[2:] == [HELD] * 8
    assert driver.stops == 2
    assert [f.index for f in inner.frames] == list(range(8))  # call k hands over frame k - 2
    assert inner.frames[0].pose == _frame(0).pose  # the delayed frame keeps its own pose


def test_delay_with_drops_never_hands_over_old_frames():
    """Every frame arrives delay_frames periods late: a delivered frame is always frame k - delay."""
    driver, inner = _driver(Perturbation(delay_frames=2, drop_rate=0.4, hold_s=10.0), seed=3)
    calls = []
    for k in range(200):
        before = len(inner.frames)
        driver.act(_frame(k))
        if len(inner.frames) > before:
            calls.append((k, inner.frames[-1].index))
    assert calls and all(k - idx == 2 for k, idx in calls)


def test_pose_noise_changes_the_pose_not_the_image():
    driver, inner = _driver(Perturbation(pose_noise_m=0.5, pose_noise_deg=5.0))
    frames = [_frame(i, np.random.default_rng(i).integers(0, 5, size=(H, W), dtype=np.uint8)) for i in range(50)]
    for f in frames:
        driver.act(f)
    assert len(inner.frames) == 50
    dxy, dyaw = [], []
    for seen, f in zip(inner.frames, frames):
        np.testing.assert_array_equal(seen.image, f.image)
        assert seen.index == f.index and seen.time_s == f.time_s
        dxy += [seen.pose[0] - f.pose[0], seen.pose[1] - f.pose[1]]
        dyaw.append(seen.pose[2] - f.pose[2])
    dxy, dyaw = np.array(dxy), np.degrees(dyaw)
    assert np.all(dxy != 0) and np.all(dyaw != 0)
    assert 0.3 < dxy.std() < 0.7
    assert 3.0 < dyaw.std() < 7.0
    assert isinstance(inner.frames[0].pose, Pose)


def test_position_noise_only_leaves_heading():
    driver, inner = _driver(Perturbation(pose_noise_m=0.2))
    f = _frame(4)
    driver.act(f)
    seen = inner.frames[0]
    assert seen.pose[2] == f.pose[2] and seen.pose[:2] != f.pose[:2]


def test_flips_reach_the_inner_driver_but_not_the_frame():
    driver, inner = _driver(Perturbation(flip_rate=0.5))
    f = _frame(0)
    driver.act(f)
    np.testing.assert_array_equal(f.image, _image(0))
    assert 0.3 < float(np.mean(inner.frames[0].image != 0)) < 0.5
    assert inner.frames[0].pose == f.pose


# --- one perturbed closed-loop run -----------------------------------------------------------------


def test_perturbed_run_one():
    spec = RunSpec(scenario="demo_course", seed=0, driver=PURE_PURSUIT, model_path=None, profile=PROFILE,
                   perturb=Perturbation(drop_rate=0.3))
    out = run_one(spec)
    assert out.scenario == "demo_course" and out.driver == PURE_PURSUIT and out.seed == 0
    m = out.metrics
    assert {"completed", "collisions", "duration_s", "rms_cross_track_m", "max_cross_track_m",
            "rms_cross_track_outside_zones_m", "distance_m", "zones"} <= set(out.to_dict()["metrics"])
    assert m.completed and m.duration_s > 0 and len(m.zones) > 0
    assert out.xy.ndim == 2 and out.xy.shape[1] == 2
    clean = run_one(RunSpec(scenario="demo_course", seed=0, driver=PURE_PURSUIT, model_path=None, profile=PROFILE))
    assert not np.array_equal(out.xy, clean.xy)  # the drops did change the drive
    again = run_one(spec)
    np.testing.assert_array_equal(out.xy, again.xy)  # and reproducibly
