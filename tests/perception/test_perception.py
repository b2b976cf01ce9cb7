"""Perception models: the file format and presets, label errors, the tilted camera, pose errors,
frame timing, the driver behind a perceiver, and perceived runs and recordings."""

from __future__ import annotations

import math
import zlib
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from terrapref.camera import CameraConfig, PinholeCamera, SegmentationRenderer, SegmentationView
from terrapref.errors import UserError
from terrapref.perception import (
    PRESETS,
    CameraJitter,
    FrameTiming,
    LabelErrors,
    PerceivedDriver,
    Perceiver,
    PerceptionModel,
    PoseErrors,
    load_perception,
    run_stream,
)
from terrapref.perception.labels import LabelledView, LabelNoise, far_pixels
from terrapref.perception.perceiver import TiltedView
from terrapref.scenario import resolve_scenario
from terrapref.sim.loop import Frame
from terrapref.terrain import default_classes
from terrapref.vehicle import Command, Pose
from terrapref.world import rasterise

HELD = Command(1.0, 0.3)
STOP = Command(0.0, 0.0)


@pytest.fixture(scope="module")
def renderer() -> SegmentationRenderer:
    return SegmentationRenderer(PinholeCamera(), rasterise(resolve_scenario("demo_course")))


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "p.yaml"
    path.write_text("format: terrapref-perception/1\n" + text)
    return path


# --- the file format and the presets -------------------------------------------------------------


def test_presets_load_and_clean_is_the_truth():
    assert PRESETS == ("clean", "rellis", "field")
    clean, rellis, field = (load_perception(name) for name in PRESETS)
    assert not clean.active and clean == PerceptionModel()
    assert rellis.labels.active and not (rellis.pose.active or rellis.camera.active or rellis.frames.active)
    assert field.labels == rellis.labels  # field is rellis plus the rest
    assert field.pose.active and field.camera.active and field.frames.active
    assert load_perception(None) == clean


def test_a_part_keeps_one_section_and_is_named_for_it():
    field = load_perception("field")
    part = load_perception("field:pose")
    assert part.pose == field.pose and not (part.labels.active or part.camera.active or part.frames.active)
    assert part.name == "field:pose"
    with pytest.raises(UserError):
        load_perception("field:nonsense")


def test_a_file_round_trips_through_to_dict(tmp_path: Path):
    path = _write(
        tmp_path,
        "labels: {flip_rate: 0.05, confusion: {water: {grass: 0.4, mud: 0.1}}, max_range_m: 20}\n"
        "pose: {noise_m: 0.3, drift_deg_per_m: 0.5}\ncamera: {pitch_jitter_deg: 2}\nframes: {delay: 1, drop_rate: 0.1}\n",
    )
    model = load_perception(path)
    assert model.labels.flip_rate == 0.05 and model.labels.confusion_dict() == {"water": {"grass": 0.4, "mud": 0.1}}
    assert model.pose == PoseErrors(noise_m=0.3, drift_deg_per_m=0.5)
    assert model.camera == CameraJitter(pitch_jitter_deg=2.0)
    assert model.frames == FrameTiming(delay=1, drop_rate=0.1)
    from terrapref.perception.model import from_dict

    assert from_dict(model.to_dict(), "meta.json", default_classes()) == model


@pytest.mark.parametrize("name", PRESETS)
def test_the_printed_preset_is_a_file_perception_reads_back(tmp_path: Path, capsys, name: str):
    from terrapref.cli import main

    assert main(["perception", name]) == 0
    path = tmp_path / f"{name}.yaml"
    path.write_text(capsys.readouterr().out)  # terrapref perception NAME > NAME.yaml
    model = load_perception(path)
    assert model == replace(load_perception(name), name=str(path))
    assert main(["perception", str(path)]) == 0


@pytest.mark.parametrize(
    "text,field",
    [
        ("labels: {flip_rate: 1.5}\n", "labels.flip_rate"),
        ("labels: {flip_rate: x}\n", "labels.flip_rate"),
        ("labels: {boundary_px: 2.5}\n", "labels.boundary_px"),
        ("labels: {blob_radius_px: [10]}\n", "labels.blob_radius_px"),
        ("labels: {blob_radius_px: [30, 10]}\n", "labels.blob_radius_px"),
        ("labels: {confusion: {lava: {grass: 0.1}}}\n", "labels.confusion.lava"),
        ("labels: {confusion: {mud: {mud: 0.1}}}\n", "labels.confusion.mud.mud"),
        ("labels: {confusion: {mud: {grass: 0.7, rock: 0.6}}}\n", "labels.confusion.mud"),
        ("labels: {colour: 3}\n", "labels.colour"),
        ("pose: {noise_m: -1}\n", "pose.noise_m"),
        ("pose: 3\n", "pose"),
        ("camera: {pitch_jitter_deg: .nan}\n", "camera.pitch_jitter_deg"),
        ("frames: {delay: -1}\n", "frames.delay"),
        ("frames: {drop_rate: true}\n", "frames.drop_rate"),
        ("wind: 3\n", "wind"),
    ],
)
def test_a_bad_file_is_refused_naming_the_file_and_field(tmp_path: Path, text: str, field: str):
    path = _write(tmp_path, text)
    with pytest.raises(UserError) as err:
        load_perception(path)
    assert any(line.startswith(f"{path}: {field}:") for line in err.value.lines()), err.value.lines()


def test_the_command_line_refuses_a_bad_file_in_one_line(tmp_path: Path, capsys):
    from terrapref.cli import main

    path = _write(tmp_path, "frames: {drop_rate: 2}\n")
    assert main(["perception", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {path}: frames.drop_rate: must be in [0, 1], got 2"]
    assert main(["evaluate", "missing.safetensors", "demo_course", "--out", str(tmp_path / "e"), "--perception", "nowhere"]) == 2
    assert main(["perception"]) == 0
    listed = capsys.readouterr().out
    assert all(f"{name}:" in listed for name in PRESETS)


def test_scaling_multiplies_the_errors_and_caps_the_shares():
    field = load_perception("field")
    double = field.scaled(2.0)
    assert double.pose.noise_m == 2 * field.pose.noise_m and double.camera.pitch_jitter_deg == 2 * field.camera.pitch_jitter_deg
    assert double.frames.delay == 2 * field.frames.delay and double.labels.boundary_px == 2 * field.labels.boundary_px
    for _, row in field.scaled(10.0).labels.confusion:
        assert sum(p for _, p in row) <= 1.0 + 1e-12
    assert not field.part("pose").scaled(0.0).active


# --- label errors ----------------------------------------------------------------------------------


def _labelled(renderer: SegmentationRenderer, errors: LabelErrors, seed: int, pose: Pose = Pose(8.0, 10.0, 0.2)) -> LabelledView:
    noise = LabelNoise(errors, renderer.camera, default_classes())
    rng = np.random.default_rng(seed)
    noise.reset(rng)
    return LabelledView(SegmentationView(renderer, pose), noise.draw(rng, 0))


def test_perceived_views_read_a_pixel_set_as_its_indices(renderer):
    from terrapref.camera import PixelSet

    index = np.random.default_rng(4).integers(0, 640 * 480, 2000)
    pixels = PixelSet(index)
    errors = LabelErrors(flip_rate=0.05, blobs_per_frame=2.0, boundary_px=2)
    for view in (
        _labelled(renderer, errors, 3),
        TiltedView(renderer, Pose(8.0, 10.0, 0.2), 0.01, math.radians(3.0)),
        LabelledView(TiltedView(renderer, Pose(8.0, 10.0, 0.2), 0.01, 0.0), _labelled(renderer, errors, 5)._errors),
    ):
        np.testing.assert_array_equal(view.pixels(pixels), view.pixels(index))
        np.testing.assert_array_equal(view.pixels(pixels), view.image.reshape(-1)[index])


ALL_ERRORS = LabelErrors(flip_rate=0.1, blobs_per_frame=3.0, boundary_px=3, confusion=(("grass", (("mud", 0.3),)),), max_range_m=12.0)


def test_label_errors_give_a_pixel_the_whole_frames_value_in_any_order(renderer):
    for seed in range(3):
        lazy, whole = _labelled(renderer, ALL_ERRORS, seed), _labelled(renderer, ALL_ERRORS, seed)
        idx = np.random.default_rng(seed).integers(0, 480 * 640, 3000)
        first = lazy.pixels(idx)
        assert not lazy.rendered  # only those pixels were worked out
        np.testing.assert_array_equal(first, whole.image.reshape(-1)[idx])
        np.testing.assert_array_equal(lazy.pixels(idx[::-1]), first[::-1])
        np.testing.assert_array_equal(lazy.image, whole.image)


def test_flips_relabel_their_share_uniformly_over_the_table(renderer):
    clean = SegmentationView(renderer, Pose(8.0, 10.0, 0.2)).image
    out = _labelled(renderer, LabelErrors(flip_rate=0.5), 1).image
    changed = out != clean
    assert 0.35 < changed.mean() < 0.45  # half redrawn, a fifth of those to the class it was
    counts = np.bincount(out[changed & (clean == 0)], minlength=5)[1:]  # grass redrawn: to each other class alike
    assert counts.min() > 0.8 * counts.mean()


def test_a_confusion_sees_its_share_of_a_class_as_another_in_whole_regions(renderer):
    clean = SegmentationView(renderer, Pose(8.0, 10.0, 0.2)).image
    grass = clean == 0
    shares = []
    for seed in range(20):
        out = _labelled(renderer, LabelErrors(confusion=(("grass", (("mud", 0.3),)),), region_px=16), seed).image
        assert np.array_equal(out[~grass], clean[~grass])  # only grass is confused
        assert set(np.unique(out[grass])) <= {0, 4}
        shares.append(float((out[grass] == 4).mean()))
        # Whole tiles at once: within a 16 px tile, grass is all grass or all mud.
        tiles = (out == 4)[:480, :640].reshape(30, 16, 40, 16).transpose(0, 2, 1, 3).reshape(30, 40, 256)
        g = grass.reshape(30, 16, 40, 16).transpose(0, 2, 1, 3).reshape(30, 40, 256)
        for t, m in zip(tiles.reshape(-1, 256), g.reshape(-1, 256)):
            assert len(set(t[m].tolist())) <= 1
    assert 0.2 < float(np.mean(shares)) < 0.4


def test_persisting_confusions_repeat_for_their_frames_and_then_change(renderer):
    errors = LabelErrors(confusion=(("grass", (("mud", 0.5),)),), persist_frames=3)
    noise = LabelNoise(errors, renderer.camera, default_classes())
    rng = np.random.default_rng(0)
    noise.reset(rng)
    view = SegmentationView(renderer, Pose(8.0, 10.0, 0.2))
    frames = [LabelledView(view, noise.draw(rng, k)).image for k in range(6)]
    assert np.array_equal(frames[0], frames[1]) and np.array_equal(frames[1], frames[2])
    assert not np.array_equal(frames[2], frames[3]) and np.array_equal(frames[3], frames[5])


def test_boundary_errors_change_pixels_near_a_border_only(renderer):
    clean = SegmentationView(renderer, Pose(8.0, 10.0, 0.2)).image
    out = _labelled(renderer, LabelErrors(boundary_px=2), 3).image
    changed = np.argwhere(out != clean)
    assert len(changed) > 0
    for r, c in changed[::7]:
        window = clean[max(0, r - 2) : r + 3, max(0, c - 2) : c + 3]
        assert out[r, c] in window  # a neighbour's class, from within the reach
        assert len(np.unique(window)) > 1  # and only beside a border


def test_ground_beyond_the_range_is_unknown(renderer):
    out = _labelled(renderer, LabelErrors(max_range_m=8.0), 0).image
    far = far_pixels(renderer.camera.config, 8.0).reshape(out.shape)
    assert (out[far] == 255).all() and (out[~far] != 255).all()
    # Down the middle column, ground 8 m from a camera 1 m up is seen asin(1 / 8) below the
    # horizon, 30 degrees above the optical axis: the first row nearer than that is there.
    first_near = int(np.argmin(far.reshape(480, 640)[:, 320]))
    assert abs(first_near - (240 - 320 * math.tan(math.radians(30) - math.asin(1 / 8)))) <= 1.5


def test_blobs_are_one_class_each_on_the_ground_half(renderer):
    painted = 0
    for seed in range(10):
        view = _labelled(renderer, LabelErrors(blobs_per_frame=2.0), seed)
        blobs = view._errors.blobs
        for cy, cx, ry, rx, cls in blobs:
            assert cy >= 240 and ry <= rx and cls in range(5)
        painted += len(blobs)
    assert painted > 5


# --- the tilted camera -------------------------------------------------------------------------------


def test_an_untilted_camera_sees_what_the_renderer_renders(renderer):
    pose = Pose(8.0, 10.0, 0.2)
    tilted = TiltedView(renderer, pose, 0.0, 0.0).image
    clean = SegmentationView(renderer, pose).image
    assert (tilted != clean).mean() < 1e-3  # float64 rays against the renderer's float32 rows: a few cell edges


def test_pitching_down_brings_the_ground_nearer_by_the_closed_form_distance():
    cam = PinholeCamera()
    for dp in (math.radians(2.0), math.radians(-2.0)):
        axes = cam.tilted(dp, 0.0)
        forward = axes[2]
        # The optical axis meets the ground 1 m / tan(30 deg + dp) ahead.
        s = -cam.t[2] / forward[2]
        assert math.isclose(cam.t[0] + s * forward[0], 1.0 / math.tan(math.radians(30.0) + dp), rel_tol=1e-12)
    roll = cam.tilted(0.0, math.radians(5.0))
    assert np.allclose(roll[2], cam.R[2]) and np.allclose(np.linalg.det(roll), 1.0)


def test_a_rolled_camera_tilts_the_horizon(renderer):
    view = TiltedView(renderer, Pose(8.0, 10.0, 0.2), 0.0, math.radians(5.0)).image
    sky = view == 255
    left, right = int(sky[:, 20].sum()), int(sky[:, 620].sum())
    assert abs(left - right) > 20  # one side of the horizon higher than the other


# --- pose errors and frame timing --------------------------------------------------------------------


def _frame(i: int, pose: Pose | None = None, view: SegmentationView | None = None) -> Frame:
    view = view or SegmentationView.of(np.zeros((480, 640), dtype=np.uint8))
    return Frame(index=i, time_s=0.1 * i, view=view, pose=pose or Pose(0.5 * i, 0.0, 0.0), waypoints=np.array([[0.0, 0.0], [10.0, 0.0]]))


def _perceiver(model: PerceptionModel, renderer: SegmentationRenderer, seed: int = 0) -> Perceiver:
    p = Perceiver(model, renderer, default_classes())
    p.reset(np.random.default_rng(seed))
    return p


def test_pose_noise_has_its_spread_and_no_drift(renderer):
    p = _perceiver(PerceptionModel(pose=PoseErrors(noise_m=0.3, noise_deg=3.0)), renderer)
    err = np.array([np.subtract(p(_frame(i)).pose, _frame(i).pose) for i in range(400)])
    assert 0.25 < err[:, 0].std() < 0.35 and 0.25 < err[:, 1].std() < 0.35
    assert 2.5 < np.degrees(err[:, 2]).std() < 3.5
    assert abs(err[:200, 0].mean() - err[200:, 0].mean()) < 0.1  # no wander


def test_drift_grows_with_the_square_root_of_the_distance_driven(renderer):
    finals = []
    for seed in range(200):
        p = _perceiver(PerceptionModel(pose=PoseErrors(drift_m_per_m=0.1)), renderer, seed)
        for i in range(51):  # 0.5 m a frame: 25 m
            told = p(_frame(i)).pose
        finals.append(told[0] - _frame(50).pose[0])
    assert 0.4 < np.std(finals) < 0.6  # 0.1 m x sqrt(25)
    still = _perceiver(PerceptionModel(pose=PoseErrors(drift_m_per_m=0.1)), renderer)
    assert {still(_frame(i, Pose(3.0, 4.0, 0.0))).pose for i in range(10)} == {Pose(3.0, 4.0, 0.0)}  # no driving, no drift


def test_delayed_frames_arrive_late_with_their_own_pose(renderer):
    p = _perceiver(PerceptionModel(frames=FrameTiming(delay=2)), renderer)
    got = [p(_frame(i)) for i in range(8)]
    assert got[:2] == [None, None]
    assert [g.index for g in got[2:]] == list(range(6))
    assert got[2].pose == _frame(0).pose and got[2].time_s == 0.0


def test_lost_and_late_frames(renderer):
    p = _perceiver(PerceptionModel(frames=FrameTiming(drop_rate=1.0)), renderer)
    assert all(p(_frame(i)) is None for i in range(10))
    p = _perceiver(PerceptionModel(frames=FrameTiming(late_rate=0.3, drop_rate=0.2)), renderer, seed=4)
    got = [g.index for g in (p(_frame(i)) for i in range(400)) if g is not None]
    assert got == sorted(set(got))  # never a frame older than one delivered
    assert 0.5 < len(got) / 400 < 0.8


def test_each_part_draws_from_its_own_stream(renderer):
    """Switching camera jitter on leaves the pose errors' draws as they were."""
    pose_only = PerceptionModel(pose=PoseErrors(noise_m=0.2))
    both = PerceptionModel(pose=PoseErrors(noise_m=0.2), camera=CameraJitter(pitch_jitter_deg=2.0))
    a, b = _perceiver(pose_only, renderer, 7), _perceiver(both, renderer, 7)
    assert [a(_frame(i)).pose for i in range(20)] == [b(_frame(i)).pose for i in range(20)]


# --- the driver behind a perceiver --------------------------------------------------------------------


class FakeDriver:
    def __init__(self) -> None:
        self.frames: list = []

    def reset(self, scenario, rng) -> None:
        self.frames = []

    def act(self, frame) -> Command:
        self.frames.append(frame)
        return HELD


def test_the_last_command_is_held_then_the_vehicle_stops(renderer):
    inner = FakeDriver()
    driver = PerceivedDriver(inner, Perceiver(PerceptionModel(frames=FrameTiming(delay=1)), renderer, default_classes()), hold_s=0.3)
    driver.reset(None, np.random.default_rng(0))
    assert driver.act(_frame(0)) == STOP  # nothing has arrived yet
    assert [driver.act(_frame(i)) for i in range(1, 5)] == [HELD] * 4
    driver.perceiver.model = PerceptionModel(frames=FrameTiming(delay=1, drop_rate=1.0))  # the camera stops
    out = [driver.act(_frame(i)) for i in range(5, 10)]
    # The newest frame decided on was taken at 0.4 s (frame 4 arrived at frame 5): held to 0.7 s.
    assert out == [HELD, HELD, HELD, STOP, STOP]


def test_a_perceived_run_is_reproducible_and_differs_from_the_clean_one():
    from terrapref.evaluation.runner import PURE_PURSUIT, RunSpec, run_one

    profile = ("mud", "rock", "water", "non_traversable")
    spec = RunSpec("demo_course", 0, PURE_PURSUIT, None, profile, perception=load_perception("field"))
    a, b = run_one(spec), run_one(spec)
    clean = run_one(RunSpec("demo_course", 0, PURE_PURSUIT, None, profile))
    np.testing.assert_array_equal(a.xy, b.xy)
    assert not np.array_equal(a.xy, clean.xy)
    # Pure pursuit keeps to the path, across the lone non_traversable patch: it drives up to it and stops there, untouched.
    assert a.metrics.progress_m > 25.0 and a.metrics.collisions == 0 and a.metrics.stops_s.get("no_free_way", 0.0) > 0


def test_runs_of_one_seed_on_different_layouts_see_different_errors(renderer):
    """A study drives every layout with seed 0: one drift shared by all of them would bias them alike."""
    model = PerceptionModel(pose=PoseErrors(drift_m_per_m=0.05))

    def told(name: str) -> list:
        driver = PerceivedDriver(FakeDriver(), Perceiver(model, renderer, default_classes()))
        driver.reset(SimpleNamespace(name=name), np.random.default_rng(0))
        for i in range(30):
            driver.act(_frame(i))
        return [f.pose for f in driver.inner.frames]

    assert told("gen_1") == told("gen_1")
    assert told("gen_1") != told("gen_2")


def test_models_of_different_draws_see_different_errors_on_one_layout(renderer):
    """The reproduction drives each training seed's model on the same layout and seed: each of
    its own draw, so that five models are five samples of the robot's errors, not one."""
    model = PerceptionModel(pose=PoseErrors(drift_m_per_m=0.05))

    def told(draw: int) -> list:
        driver = PerceivedDriver(FakeDriver(), Perceiver(model, renderer, default_classes()), draw=draw)
        driver.reset(SimpleNamespace(name="test_course"), np.random.default_rng(0))
        for i in range(30):
            driver.act(_frame(i))
        return [f.pose for f in driver.inner.frames]

    assert told(1) == told(1) and told(2) == told(2)
    assert len({str(told(d)) for d in range(3)}) == 3
    # Draw 0 is the stream every run had before draws: select, study and evaluate meet the same errors as ever.
    rng = np.random.default_rng(7)
    np.testing.assert_array_equal(
        run_stream(np.random.default_rng(7), "test_course", 0).random(3),
        np.random.default_rng([int(rng.integers(2**63)), zlib.crc32(b"test_course")]).random(3),
    )


# --- the planner's reading of the camera's attitude from the sky line ----------------------------------


def test_the_sky_line_gives_the_cameras_pitch_and_roll(renderer):
    """Five frames at the mount's attitude set the reference; a frame tilted by a known pitch and
    roll is read back within a tenth of a degree; a frame at the mount reads as no tilt at all."""
    from terrapref.groundmap.attitude import HorizonAttitude

    estimate = HorizonAttitude(renderer.camera)
    pose = Pose(20.0, 15.0, 0.3)
    for _ in range(5):
        assert estimate(TiltedView(renderer, pose, 0.0, 0.0)) == (0.0, 0.0)
    for dp, dr in ((2.0, 0.0), (-1.5, 1.0), (0.5, -2.5)):
        got = estimate(TiltedView(renderer, pose, math.radians(dp), math.radians(dr)))
        assert abs(math.degrees(got[0]) - dp) < 0.1 and abs(math.degrees(got[1]) - dr) < 0.15, (dp, dr, np.degrees(got))
    estimate.reset()
    for _ in range(6):
        assert estimate(SegmentationView(renderer, pose)) == (0.0, 0.0)


def test_a_sky_line_the_map_cuts_short_gives_no_estimate(renderer):
    from terrapref.groundmap.attitude import HorizonAttitude

    estimate = HorizonAttitude(renderer.camera)
    for _ in range(5):
        estimate(SegmentationView(renderer, Pose(20.0, 15.0, 0.0)))
    # Facing the map's edge 3 m away: the sky line is the map's edge, far below the reference.
    assert estimate(SegmentationView(renderer, Pose(57.0, 15.0, 0.0))) == (0.0, 0.0)


# --- perceived recordings, evaluations and environments -------------------------------------------------


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_a_recording_under_perception_holds_what_the_robot_received(tmp_path, capsys, short_recording):
    """The driver sees the truth (the same drive as without perception); the recording holds the
    frames that reached the robot (fewer, late, their labels and poses off the truth) and names
    the model; it is featurised and trained from as any recording."""
    import json

    from helpers import SHORT_COURSE
    from terrapref.cli import main
    from terrapref.demos.recording import read_recording
    from terrapref.perception.model import from_dict

    clean, seen = short_recording, tmp_path / "seen"
    assert main(["record", str(SHORT_COURSE), "--out", str(seen), "--quiet", "--disturb", "0", "--perception", "field"]) == 0
    assert "under perception field" in capsys.readouterr().out
    a, b = read_recording(clean), read_recording(seen)
    assert a.meta["perception"]["name"] == "clean" and from_dict(b.meta["perception"], "meta", default_classes()) == load_perception(
        "field"
    )
    assert a.meta["summary"] == b.meta["summary"]  # the same drive
    assert 0.8 * len(a) < len(b) < len(a)  # lost and stale frames are not written
    times = b.times
    assert (np.diff(times) > 0).all()
    lines = [json.loads(x) for x in (seen / "frames.jsonl").read_text().splitlines()]
    first = lines[0]
    # No frame arrives before one period has passed (field's delay); the first that does is logged
    # with the pose of the moment it was taken, a period or more before.
    period = round(first["t"] / 0.1)
    assert period >= 1 and first["t"] == pytest.approx(0.1 * period)
    assert any(first["pose"] == pytest.approx(list(a.poses[i]), abs=1.0) for i in range(period))
    differ = [not np.array_equal(a.image(i), b.image(i)) for i in range(0, min(len(a), len(b)), 50)]
    assert all(differ)


@pytest.mark.slow  # a whole evaluation end to end, its steps tested apart in the default run
def test_evaluate_under_a_perception_preset_names_it_in_metrics_json(tmp_path, capsys):
    import json

    from helpers import SHORT_COURSE, linear_model
    from terrapref.cli import main

    model = linear_model(tmp_path / "m.safetensors")
    out = tmp_path / "ev"
    assert (
        main(["evaluate", str(model), str(SHORT_COURSE), "--seeds", "1", "--out", str(out), "--perception", "field", "--workers", "1"]) == 0
    )
    assert "perception: field" in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["perception"] == load_perception("field").to_dict()
    assert metrics["summary"]["runs"] == 1 and metrics["driver_summary"]["runs"] == 1


def test_the_gymnasium_env_observes_what_the_robot_would(tmp_path):
    from terrapref.sim.env import OffRoadNavEnv

    clean, seen = OffRoadNavEnv("demo_course"), OffRoadNavEnv("demo_course", perception="field")
    a, _ = clean.reset(seed=3)
    b, _ = seen.reset(seed=3)
    assert not np.array_equal(a["image"], b["image"]) and not np.array_equal(a["pose"], b["pose"])
    again, _ = OffRoadNavEnv("demo_course", perception="field").reset(seed=3)
    assert all(np.array_equal(b[k], again[k]) for k in b)
    repeats = 0
    last = b
    for _ in range(60):
        obs, *_ = seen.step(10)
        repeats += all(np.array_equal(obs[k], last[k]) for k in obs)  # a period in which no frame arrived
        last = obs
    assert 0 < repeats < 20
    with pytest.raises(UserError):
        OffRoadNavEnv("demo_course", perception="nowhere")


def test_a_recordings_perception_is_checked_when_it_is_read(tmp_path, tiny_recording):
    import json
    import shutil

    from terrapref.demos.recording import read_recording

    out = shutil.copytree(tiny_recording, tmp_path / "rec")
    meta = json.loads((out / "meta.json").read_text())
    meta["perception"] = load_perception("rellis").to_dict()  # the section a recording made under rellis carries
    (out / "meta.json").write_text(json.dumps(meta))
    assert read_recording(out).meta["perception"]["name"] == "rellis"
    meta["perception"]["labels"]["flip_rate"] = 7
    (out / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(UserError) as err:
        read_recording(out)
    assert err.value.lines() == [f"{out / 'meta.json'}: perception.labels.flip_rate: must be in [0, 1], got 7"]
    meta["perception"] = "field"
    (out / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(UserError, match="perception: expected a mapping"):
        read_recording(out)


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_select_drives_the_same_models_under_several_perception_models(tmp_path):
    """The paper's recipe (quick to train) taught from a drive of the short course recorded under
    field, driving one layout on clean frames and under rellis: one table each, every zone tagged."""
    import json

    from helpers import SHORT_COURSE
    from terrapref.cli import main

    out = tmp_path / "sel"
    argv = [
        "select",
        "--course",
        str(SHORT_COURSE),
        "--recipes",
        "paper",
        "--orders",
        "rock,mud,water",
        "--seeds",
        "1",
        "--courses",
        "1",
        "--workers",
        "2",
        "--perception",
        "clean,rellis",
        "--taught-under",
        "field",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    saved = json.loads((out / "select.json").read_text())
    assert [p["name"] for p in saved["selection"]["perceptions"]] == ["clean", "rellis"]
    assert saved["selection"]["taught_under"]["name"] == "field"
    assert {r["perception"] for r in saved["zones"]} == {"clean", "rellis"}
    assert (
        len([r for r in saved["zones"] if r["perception"] == "clean"])
        == len([r for r in saved["zones"] if r["perception"] == "rellis"])
        > 0
    )
    text = (out / "SELECT.md").read_text()
    assert "## Perception `clean`" in text and "## Perception `rellis`" in text and "The demonstrations recorded: field" in text
    assert list((out / "work").iterdir())[0].name.endswith("_field")


def test_select_and_reproduce_refuse_a_bad_perception_before_any_work(tmp_path, capsys):
    from terrapref.cli import main

    for argv, flag in (
        (["select", "--perception", "fog"], "--perception"),
        (["select", "--perception", "clean,clean"], "--perception"),
        (["select", "--taught-under", "fog"], "--taught-under"),
        (["select", "--perception", "clean,field", "--taught-under", "same"], "--taught-under"),
        (["reproduce", "--perception", "rellis,fog"], "--perception"),
    ):
        assert main([*argv, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and flag in err[0], err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_reproduce_reports_each_recipe_under_each_perception_model(tmp_path):
    """REPORT.md holds a row per recipe and a column per perception model, each cell from runs
    driven under that model (the field cell is not the clean one)."""
    import json

    from terrapref.recipes import TEACH
    from terrapref.report.reproduce import Reproduction, reproduce

    setup = Reproduction(
        recipes=(TEACH,), seeds=1, perceptions=(load_perception("clean"), load_perception("field")), speed_seeds=0, relief_seeds=0
    )
    report_path = reproduce(tmp_path / "rep", setup, log=lambda _: None)
    report = report_path.read_text()
    table = report.split("## Under what a robot sees")[1].split("\n## ")[0]
    header = next(line for line in table.splitlines() if line.startswith("| recipe |"))
    assert header == "| recipe | clean | field |"
    row = next(line for line in table.splitlines() if line.startswith("| teach |"))
    clean, field = row.split(" | ")[1:3]
    assert "collisions" in clean and "collisions" in field
    runs = json.loads((report_path.parent / "results.json").read_text())["runs"]
    seen = {r["perception"] for r in runs}
    assert seen == {"clean", "field"}
    # The same test courses driven under each: the field runs are runs of their own, not the clean ones relabelled.
    tracks = {r["perception"]: [z["distance_m"] for z in r["metrics"]["zones"]] for r in runs if r["scenario"] == "test_course"}
    assert tracks["clean"] != tracks["field"]


def test_confusion_tiles_from_the_tables_are_the_divisions():
    """Each pixel's confusion tile from LabelNoise's row and column tables equals row // region *
    tiles across + col // region, for regions that divide the image and that do not."""
    for region, shape in ((32, (480, 640)), (7, (211, 333)), (1, (20, 30))):
        camera = PinholeCamera(CameraConfig(width_px=shape[1], height_px=shape[0]))
        noise = LabelNoise(LabelErrors(region_px=region), camera, default_classes())
        rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
        want = rows // region * ((shape[1] + region - 1) // region) + cols // region
        np.testing.assert_array_equal(noise.tile_of_row[rows] + noise.tile_of_col[cols], want)
