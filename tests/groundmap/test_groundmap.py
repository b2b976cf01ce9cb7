"""The ground map's layers (terrapref.groundmap.layers) and the maps the planner keeps for the rules."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_offset_rule import CONTROL, DRIVER_LIKE, TREES, _offset_meta, _scenario, _seen_from, _terrain
from test_speed_rule import MODEL as SPEED_MODEL

from helpers import skip_path_weights
from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.groundmap.layers import LAYERS, Layer
from terrapref.groundmap.map import GroundMap
from terrapref.learning.model_file import load_model, save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.planner import Planner
from terrapref.rules.offset.fit import OffsetUtility
from terrapref.rules.offset.rule import OffsetSteering
from terrapref.rules.speed.rule import SpeedConfig, SpeedRule
from terrapref.scenario.path import ReferencePath


class HeightMap(GroundMap):
    """A ground map with one more layer, as a height from a depth sensor would be added: one
    entry in the list, and the code that writes it (here: the frame number under the vehicle)."""

    LAYERS = (*LAYERS, Layer("height", np.float32, np.nan))

    def update(self, view: SegmentationView, pose) -> None:
        super().update(view, pose)
        i, j = self.cell_of(pose[0], pose[1])
        self.layer("height")[j, i] = self.frame

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        res = self.settings.map_resolution_m
        return int(np.floor((x - self.origin[0]) / res)), int(np.floor((y - self.origin[1]) / res))


def test_a_layer_added_to_the_list_moves_and_empties_with_the_map():
    camera = PinholeCamera()
    scenario = _scenario([TREES])
    plain, tall = GroundMap(camera, _terrain((0,))), HeightMap(camera, _terrain((0,)))
    height = tall.layer("height")
    assert height.shape == tall.layer("column").shape and height.dtype == np.float32 and np.isnan(height).all()
    first, far = (4.0, 10.0, 0.0), (24.0, 10.0, 0.0)  # 20 m on: past the 17 m the map lets the vehicle go before re-centring
    corners = []
    for pose in (first, far):
        view = _seen_from(scenario, camera, pose)
        plain.update(view, pose)
        tall.update(view, pose)
        corners.append(tall.origin[0])
    assert corners[1] - corners[0] == 20.0  # re-centred: the square moved on
    i, j = tall.cell_of(*first[:2])
    assert tall.layer("height")[j, i] == 1.0  # the first frame's cell, moved with the square
    assert np.count_nonzero(~np.isnan(tall.layer("height"))) == 2  # and only the two written
    np.testing.assert_array_equal(tall.evidence, plain.evidence)  # the votes as a map without the layer holds them
    np.testing.assert_array_equal(tall.cells, plain.cells)
    tall.reset()
    assert np.isnan(tall.layer("height")).all() and not tall.evidence.any() and tall.origin is None


def test_a_depth_layer_written_through_the_map_moves_with_it_and_an_untouched_one_stays_empty():
    """A flat map re-centres without copying its depth layers while none may hold anything; one
    handed out (and written) moves with the square as any layer does."""
    camera = PinholeCamera()
    scenario = _scenario([TREES])
    untouched, written = GroundMap(camera, _terrain((0,))), GroundMap(camera, _terrain((0,)))
    first, far = (4.0, 10.0, 0.0), (24.0, 10.0, 0.0)  # 20 m on: re-centred
    for pose in (first, far):
        view = _seen_from(scenario, camera, pose)
        untouched.update(view, pose)
        written.update(view, pose)
        if pose == first:  # a value in the elevation layer under the vehicle, as code writing the layer would
            res = written.settings.map_resolution_m
            i, j = int((first[0] - written.origin[0]) / res), int((first[1] - written.origin[1]) / res)
            written.layer("elevation")[j, i] = 1.5
    res = written.settings.map_resolution_m
    i, j = int((first[0] - written.origin[0]) / res), int((first[1] - written.origin[1]) / res)
    assert written.layer("elevation")[j, i] == 1.5 and np.count_nonzero(~np.isnan(written.layer("elevation"))) == 1
    for layer in LAYERS:  # the untouched map: each depth layer still all its fill, each other layer as the written map's
        ours, theirs = untouched.layer(layer.name), written.layer(layer.name)
        if layer.from_depth:
            np.testing.assert_array_equal(ours, np.full_like(ours, layer.fill_value(untouched.k)))
        else:
            np.testing.assert_array_equal(ours, theirs)


def test_a_rule_reads_a_map_with_a_layer_added_as_it_reads_one_without():
    camera = PinholeCamera()
    scenario = _scenario([TREES])
    path = ReferencePath(scenario.waypoints)
    steered = []
    for gmap in (GroundMap(camera, _terrain((0,))), HeightMap(camera, _terrain((0,)))):
        stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain((0,)), CONTROL)
        for x in np.arange(6.0, 12.0, 0.5):  # up to the trees, which lie on the path from x = 13.1 m
            pose = (float(x), 10.0, 0.0)
            gmap.update(_seen_from(scenario, camera, pose), pose)
            steered.append((type(gmap), stage.yaw_rate(gmap, pose, path, x - 2.0), stage.held))
    half = len(steered) // 2
    assert [s[1:] for s in steered[:half]] == [s[1:] for s in steered[half:]]
    assert any(held != 0.0 for _, _, held in steered)  # the trees ahead moved the offset held


def test_the_planner_keeps_one_map_per_settings_updates_it_once_a_frame_and_forgets_it_with_the_path(tmp_path: Path):
    classifier = ClassifierConfig(hidden=8, skip=True)
    meta = _offset_meta(DRIVER_LIKE)
    meta["rules"].append(SpeedRule(SpeedConfig(), SPEED_MODEL).header())
    model = load_model(save_model(tmp_path / "m.safetensors", classifier, skip_path_weights(classifier), meta))
    planner = Planner(model)
    assert planner.speed is not None and list(planner._maps.values()) == [planner.ground_map]  # offset, speed and stop: one map
    scenario = _scenario([TREES])
    planner.set_path(scenario.waypoints)
    for x in (2.0, 2.5, 3.0):
        pose = (x, 10.0, 0.0)
        planner.decide(_seen_from(scenario, planner.camera, pose), pose)
    assert planner.ground_map.frame == 3 and planner.costmap() is not None
    costmap = planner.costmap()  # with the speed the speed rule cruises at on each cell, for Nav2's speed filter
    assert costmap.top_speed_mps == planner.vehicle.max_speed_mps
    speed, cost = costmap.layers["speed"], costmap.cost
    assert (speed[cost == 100] == 0.0).all() and np.isnan(speed[cost == -1]).all()
    background = np.float32(min(SPEED_MODEL.speeds_mps[-1], SpeedConfig().max_speed_mps, planner.vehicle.max_speed_mps))
    assert (speed == background).any()
    planner.set_path(scenario.waypoints)
    assert planner.ground_map.frame == 0 and planner.ground_map.origin is None
    argmax = Planner(model, rule="argmax")  # C steers and reads no map: the speed rule's, and the stop rule's small one
    assert argmax.ground_map is None and argmax.costmap() is None and len(argmax._maps) == 2


def test_a_cell_waits_for_its_evidence_lethal_or_not():
    """With ``map_min_evidence``, a cell that one far vote put in a class, lethal or not, reads as
    never seen until enough evidence gathers, then as it would without a minimum; with none
    (the default), one vote decides it."""
    from terrapref.groundmap.map_compiled import map_decide

    k = 3  # columns: two terrain classes, one lethal, then the ground (column K); K + 1: never seen
    lethal = np.array([False, False, True])
    shares = (np.float32(0.35), np.float32(0.4))
    far = np.float32(1.0 / (1.0 + (12.0 / 4.0) ** 2))  # one vote at 12 m

    def decided(votes: dict[int, float], min_evidence: float) -> int:
        evidence = np.zeros((1, 1, k + 1), np.float32)
        for column, weight in votes.items():
            evidence[0, 0, column] = weight
        return map_decide(evidence, lethal, *shares, np.float32(min_evidence), 0, 0)

    assert decided({1: far}, 0.0) == 1 and decided({1: far}, 1.0) == k + 1
    assert decided({2: far}, 0.0) == 2 and decided({2: far}, 1.0) == k + 1  # a far glimpse of lethal ground waits too
    assert decided({2: 12 * far}, 1.0) == 2  # a dozen such votes: lethal
    assert decided({2: far, k: 1.2}, 1.0) == k  # enough evidence, the lethal share not reached: the ground


def test_the_speed_rule_reads_the_steering_rules_map_whatever_its_settings(tmp_path: Path):
    """An offset rule whose geometry names other map settings than the default: the speed rule
    reads its map, so the planner still keeps and updates one."""
    classifier = ClassifierConfig(hidden=8, skip=True)
    meta = _offset_meta(DRIVER_LIKE)
    meta["rules"][0]["geometry"] = {**meta["rules"][0]["geometry"], "map_min_evidence": 0.5, "map_fade": 0.9}
    meta["rules"].append(SpeedRule(SpeedConfig(), SPEED_MODEL).header())
    planner = Planner(load_model(save_model(tmp_path / "m.safetensors", classifier, skip_path_weights(classifier), meta)))
    assert planner.ground_map.settings.map_min_evidence == 0.5 and planner.ground_map.settings.map_fade == 0.9
    assert planner.speed is not None and list(planner._maps.values()) == [planner.ground_map]


def test_a_map_setting_read_as_true_or_false_takes_nothing_else():
    """A file's "false" (a string) would read as true: it is refused."""
    from terrapref.groundmap.settings import MapSettings

    assert MapSettings(map_sky_attitude=False).map_sky_attitude is False
    with pytest.raises(ValueError, match="map_sky_attitude must be true or false, got 'false'"):
        MapSettings(map_sky_attitude="false")
