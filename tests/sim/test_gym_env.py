"""The Gymnasium environments: checkers, reward, episodes, observations, actions, seeds, clients."""

from __future__ import annotations

import doctest
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import InvalidAction, ResetNeeded
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import terrapref.sim.env
from helpers import REPO
from terrapref.scenario import Scenario, parse_scenario
from terrapref.sim import SimConfig
from terrapref.sim.env import ENV_ID, ENV_ID_CONTINUOUS, MAX_EPISODE_STEPS, EnvConfig, OffRoadNavEnv, RewardConfig

IDS = [ENV_ID, ENV_ID_CONTINUOUS]
SMALL = (48, 64)  # the smallest comfortable size for SB3's default CNN (36 x 36 at least)


def _scenario(
    terrain: list[dict] | None = None, waypoints: list[list[float]] | None = None, size: tuple[float, float] = (20.0, 10.0)
) -> Scenario:
    return parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "tiny_env",
            "world": {"size_m": list(size), "resolution_m": 0.05, "background": "grass"},
            "terrain": terrain or [],
            "path": {"waypoints": waypoints or [[2.0, 5.0], [15.0, 5.0]]},
        }
    )


def _env(scenario=None, **kwargs) -> OffRoadNavEnv:
    """The env on a small course; commands are applied at once (the paper's vehicle) unless ``sim``
    says otherwise, so that rewards are checked against closed-form distances."""
    kwargs.setdefault("sim", SimConfig.paper())
    kwargs.setdefault("start_jitter_m", 0.0)
    kwargs.setdefault("start_yaw_jitter_rad", 0.0)
    return OffRoadNavEnv(scenario if scenario is not None else _scenario(), **kwargs)


LETHAL_STRIP = {"class": "non_traversable", "rectangle": {"center": [6.0, 5.0], "size": [1.0, 4.0]}}
MUD_STRIP = {"class": "mud", "rectangle": {"center": [6.0, 5.0], "size": [1.0, 4.0]}}


# --- the checkers ------------------------------------------------------------------------------


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize(
    "kwargs", [{}, {"image_encoding": "onehot", "image_size": SMALL}, {"scenario": ["demo_course", "gen:*"], "render_mode": "rgb_array"}]
)
def test_gymnasium_and_sb3_checkers_pass_without_warnings(env_id, kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = gym.make(env_id, **kwargs)
        gymnasium_check_env(env.unwrapped, skip_render_check=False)
        sb3_check_env(env.unwrapped, warn=True)
        env.reset(seed=0)  # through gym.make's own passive checker too
        env.step(env.action_space.sample())
        env.close()
    assert [str(w.message) for w in caught] == []


def test_docstring_example_runs():
    result = doctest.testmod(terrapref.sim.env, verbose=False)
    assert result.attempted > 0 and result.failed == 0


def test_registered_time_limit_truncates():
    assert gym.spec(ENV_ID).max_episode_steps == MAX_EPISODE_STEPS
    env = gym.make(ENV_ID, scenario="demo_course", max_episode_steps=5)
    env.reset(seed=0)
    for step in range(1, 6):
        _, _, terminated, truncated, _ = env.step(10)
    assert truncated and not terminated and step == 5


# --- observations ------------------------------------------------------------------------------


def test_spaces_do_not_depend_on_the_course():
    spaces = [gym.make(ENV_ID, scenario=name).observation_space for name in ("demo_course", "test_course", "gen:3")]
    assert spaces[0] == spaces[1] == spaces[2]


def test_observation_in_the_vehicle_frame():
    env = _env(n_waypoints=4, waypoint_spacing_m=2.0)
    obs, info = env.reset(seed=0)
    np.testing.assert_allclose(obs["pose"], [0.0, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(obs["waypoints"], [2.0, 0.0, 4.0, 0.0, 6.0, 0.0, 8.0, 0.0], atol=1e-5)
    assert info["is_success"] is False and info["progress_m"] == 0.0
    # Started 1 m left of the path, turned 90 degrees left: the path lies to the right.
    obs, _ = env.reset(options={"start": (4.0, 6.0, math.pi / 2)})
    np.testing.assert_allclose(obs["pose"][:2], [1.0, math.pi / 2], atol=1e-6)
    np.testing.assert_allclose(obs["waypoints"][:2], [-1.0, -2.0], atol=1e-5)  # (6, 5) seen from (4, 6) facing north
    assert obs["pose"][2] == pytest.approx(2.0 / 13.0, abs=1e-6)


def test_image_is_the_camera_frame_sampled_by_nearest_pixel():
    scenario = _scenario(terrain=[MUD_STRIP, {"class": "water", "circle": {"center": [8.0, 3.5], "radius": 1.0}}])
    full = _env(scenario, image_size=None)
    small = _env(scenario, image_size=(60, 80))
    onehot = _env(scenario, image_size=(60, 80), image_encoding="onehot")
    image = full.reset(seed=0)[0]["image"]
    assert image.shape == (480, 640, 1)
    np.testing.assert_array_equal(image[:, :, 0], full.sim.frame().image)
    ids = small.reset(seed=0)[0]["image"][:, :, 0]
    np.testing.assert_array_equal(ids, image[4::8, 4::8, 0])  # pixel centres of 8 x 8 blocks: ids, never blends
    assert set(np.unique(ids)) <= {0, 2, 4, 255} and {2, 4} <= set(np.unique(ids))
    hot = onehot.reset(seed=0)[0]["image"]
    assert hot.shape == (60, 80, 5) and set(np.unique(hot)) == {0, 255}
    table = [c.id for c in onehot.classes.classes]
    for channel, class_id in enumerate(table):
        np.testing.assert_array_equal(hot[:, :, channel] == 255, ids == class_id)


# --- reward ------------------------------------------------------------------------------------


def test_progress_on_a_straight_path_is_the_distance_driven():
    env = _env()
    env.reset(seed=0)
    _, reward, terminated, truncated, info = env.step(10)
    assert info["reward_terms"]["progress"] == pytest.approx(0.1, abs=1e-9)
    assert reward == pytest.approx(0.1, abs=1e-9) and not terminated and not truncated
    assert info["progress_m"] == pytest.approx(0.1, abs=1e-9)


def test_no_progress_outside_the_path_band():
    env = _env(reward=RewardConfig(path_band_m=3.0), scenario=_scenario(size=(40.0, 30.0), waypoints=[[2.0, 5.0], [35.0, 5.0]]))
    env.reset(options={"start": (2.0, 15.0, 0.0)})  # 10 m from the path, driving along it
    for _ in range(50):
        _, _, _, _, info = env.step(10)
        assert info["reward_terms"]["progress"] == 0.0
    assert info["path_position_m"] == pytest.approx(5.0, abs=1e-6)  # where it is along the path,
    assert info["progress_m"] == 0.0  # though nothing was credited


def test_random_driving_earns_no_more_progress_than_it_drove():
    env = gym.make(ENV_ID, scenario="demo_course", image_size=SMALL)
    env.action_space.seed(3)
    for seed in range(3):
        _, info = env.reset(seed=seed)
        earned = driven = 0.0
        last = info["progress_m"]
        for _ in range(600):
            before = np.array(env.unwrapped.sim.vehicle.pose[:2])
            obs, _, terminated, truncated, info = env.step(env.action_space.sample())
            step = float(np.hypot(*(np.array(env.unwrapped.sim.vehicle.pose[:2]) - before)))
            assert info["reward_terms"]["progress"] <= 0.1 + 1e-9
            if info["reward_terms"]["progress"] != 0.0:  # credited only within the 5 m path band and on the map
                assert abs(obs["pose"][0]) <= 5.0 and not info["off_map"]
            earned += info["reward_terms"]["progress"]
            assert abs(info["progress_m"] - last) <= 0.1 + 1e-9  # the credited progress never jumps
            last = info["progress_m"]
            driven += step
            if terminated or truncated:
                break
        assert earned <= driven + 1e-9


def test_collision_ends_the_episode_with_one_penalty():
    env = _env(_scenario(terrain=[LETHAL_STRIP]), reward=RewardConfig(cross_track_weight=0.0))
    env.reset(seed=0)
    total = 0.0
    for _ in range(60):
        _, reward, terminated, _, info = env.step(10)
        total += reward
        if terminated:
            break
    assert terminated and info["collisions"] == 1 and not info["is_success"]
    assert info["reward_terms"]["collision"] == -10.0
    contact = info["reward_terms"]["contact"]  # 10 per second with the footprint on the strip: at most the step's 0.1 s
    assert -1.0 - 1e-9 <= contact < 0.0
    assert total == pytest.approx(info["progress_m"] - 10.0 + contact, abs=1e-9)
    with pytest.raises(ResetNeeded):
        env.step(10)
    env.reset(seed=0)  # usable again
    env.step(10)


def test_collision_need_not_end_the_episode():
    env = _env(_scenario(terrain=[LETHAL_STRIP]), terminate_on_lethal=False)
    env.reset(seed=0)
    penalties = [env.step(10)[4]["reward_terms"]["collision"] for _ in range(60)]
    assert penalties.count(-10.0) == 1 and env.sim.collisions == 1


def test_leaving_the_map_ends_the_episode():
    env = _env()
    env.reset(options={"start": (2.0, 9.0, math.pi / 2)})  # 1 m from the northern edge, facing it
    for _ in range(30):
        _, _, terminated, _, info = env.step(10)
        if terminated:
            break
    assert terminated and info["off_map"] and info["reward_terms"]["off_map"] == -10.0
    assert info["reward_terms"]["progress"] == 0.0


def test_reaching_the_goal_is_success():
    env = _env()  # straight path from (2, 5) to (15, 5), goal radius 2 m
    env.reset(seed=0)
    for step in range(1, 200):
        _, _, terminated, truncated, info = env.step(10)
        if terminated or truncated:
            break
    assert terminated and info["is_success"] and info["reward_terms"]["goal"] == 10.0
    assert step in (110, 111)  # 11 m at 1 m/s, 10 frames a second
    assert 15.0 - env.sim.vehicle.pose.x <= 2.0


def test_terrain_term_scores_the_profile():
    scenario = _scenario(terrain=[MUD_STRIP])
    for profile, rank in (("mud,rock,water,non_traversable", 0), ("rock,water,mud,non_traversable", 2)):
        env = _env(scenario, profile=profile, reward=RewardConfig(terrain_weight=1.0))
        env.reset(seed=0)
        cost = -sum(env.step(10)[4]["reward_terms"]["terrain"] for _ in range(60))
        assert cost == pytest.approx(1.5**rank * 1.0, abs=0.04)  # the 1 m strip, on the vehicle's centre
    plain = _env(scenario)
    plain.reset(seed=0)
    assert all(plain.step(10)[4]["reward_terms"]["terrain"] == 0.0 for _ in range(60))


# --- actions -----------------------------------------------------------------------------------


@pytest.mark.parametrize("action", [-1, 21, 3.7, 3.0, float("nan"), np.array([3]), np.array([[3]]), "3", True, None])
def test_bad_discrete_actions_are_refused_and_the_env_stays_usable(action):
    env = _env()
    env.reset(seed=0)
    with pytest.raises(InvalidAction, match="0..20"):
        env.step(action)
    assert env.sim.time_s == 0.0
    _, reward, _, _, _ = env.step(np.int64(10))
    assert reward == pytest.approx(0.1, abs=1e-9)


@pytest.mark.parametrize("action", [[1.0], [1.0, 0.0, 0.0], np.zeros((1, 2)), [float("nan"), 0.0], [0.0, float("inf")], "go"])
def test_bad_continuous_actions_are_refused(action):
    env = _env(action_type="continuous")
    env.reset(seed=0)
    with pytest.raises(InvalidAction):
        env.step(action)
    assert env.sim.time_s == 0.0
    env.step(np.array([1.0, 0.0], np.float32))
    assert env.sim.vehicle.pose.x == pytest.approx(2.1)


def test_continuous_actions_are_scaled_and_clipped():
    env = _env(action_type="continuous", sim=SimConfig())  # the field UGV: 0..2 m/s
    for action, command in (([1.0, 0.0], (2.0, 0.0)), ([-1.0, 0.5], (0.0, 0.5)), ([0.0, -1.0], (1.0, -1.0)), ([5.0, 2.0], (2.0, 1.0))):
        env.reset(seed=0)
        env.step(np.array(action, np.float32))
        assert tuple(env.sim.vehicle.command) == pytest.approx(command)
        assert env.sim.vehicle.speed_mps == pytest.approx(min(command[0], 0.1))  # from rest at 1 m/s^2: 0.1 m/s after one frame


# --- seeds, options, render --------------------------------------------------------------------


def test_seeds_vary_the_start_and_repeat_exactly():
    env = gym.make(ENV_ID, scenario="demo_course")
    first, _ = env.reset(seed=7)
    again, _ = env.reset(seed=7)
    other, _ = env.reset(seed=8)
    for key in first:
        np.testing.assert_array_equal(first[key], again[key])
    assert not np.array_equal(first["pose"], other["pose"])
    x, y, yaw = env.unwrapped.sim.vehicle.pose
    sx, sy, syaw = env.unwrapped.sim.scenario.start
    assert abs(x - sx) <= 0.5 and abs(y - sy) <= 0.5 and abs(yaw - syaw) <= 0.1


def test_seeded_episodes_are_identical():
    env = gym.make(ENV_ID_CONTINUOUS, scenario="demo_course", image_size=SMALL)
    runs = []
    for _ in range(2):
        obs, _ = env.reset(seed=123)
        env.action_space.seed(5)
        record = [obs]
        for _ in range(20):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            record.append((obs, reward, terminated, truncated, info["reward_terms"]))
        runs.append(record)
    for a, b in zip(*runs):
        np.testing.assert_equal(a, b)


def test_a_list_of_courses_and_generated_courses():
    env = gym.make(ENV_ID, scenario=["demo_course", "fig7_rock_vs_non_traversable_left"], image_size=SMALL)
    seen = {env.reset(seed=seed)[1]["scenario"] for seed in range(12)}
    assert seen == {"demo_course", "fig7_rock_vs_non_traversable_left"}
    gen = gym.make(ENV_ID, scenario="gen:*", image_size=SMALL)
    names = [gen.reset(seed=seed)[1]["scenario"] for seed in (1, 2, 1)]
    assert names[0] == names[2] != names[1] and all(n.startswith("gen:") for n in names)  # named as gym.make takes it
    assert all(1_000_000 <= int(n[4:]) < 2_000_000 for n in names)
    again = gym.make(ENV_ID, scenario=names[1], image_size=SMALL)
    assert again.reset(seed=0)[1]["scenario"] == names[1]


@pytest.mark.parametrize(
    "scenario,needle",
    [(5, "got int"), (["demo_course", 5], "got int"), ("no_such_course", "no_such_course"), ("gen:-1", "gen:-1")],
)
def test_a_course_that_is_not_one_is_a_value_error_naming_it(scenario, needle):
    from terrapref.sim.env import OffRoadNavEnv

    with pytest.raises(ValueError, match=needle):
        OffRoadNavEnv(scenario, image_size=SMALL)


def test_a_class_table_of_ones_own_reads_course_names_and_perception():

    examples = REPO / "examples" / "classes"
    env = gym.make(
        ENV_ID,
        scenario=["gen:7", "gen:8"],
        image_size=SMALL,
        image_encoding="onehot",
        classes=str(examples / "rellis3d.yaml"),
        perception=str(examples / "rellis3d_field.yaml"),
    ).unwrapped
    assert "bush" in env.classes.names and env.observation_space["image"].shape[-1] == len(env.classes.classes) == 13
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    names = {env.classes.name_of(int(i)) for i in np.unique(env.sim.world.raster)}
    assert names & {"dirt", "gravel", "mud", "puddle", "water", "bush"} and not names & {"rock", "non_traversable"}
    env.step(env.action_space.sample())
    with pytest.raises(ValueError, match="differs from the first course's"):
        env.reset(options={"scenario": _scenario()})  # a scenario of the default table
    with pytest.raises(ValueError, match="differs from classes="):
        OffRoadNavEnv(_scenario(), classes=str(examples / "small.yaml"))


def test_reset_options():
    env = gym.make(ENV_ID, scenario="demo_course", image_size=SMALL)
    assert env.reset(seed=0, options={"scenario": "test_course"})[1]["scenario"] == "test_course"
    assert env.reset(seed=0)[1]["scenario"] == "demo_course"  # for one episode only
    with pytest.raises(ValueError, match="unknown key 'course'"):
        env.reset(options={"course": "test_course"})
    with pytest.raises(ValueError, match="start"):
        env.reset(options={"start": (1.0, float("nan"), 0.0)})
    for bad in ("east", (1.0, "x", 0.0), {"x": 1.0}):
        with pytest.raises(ValueError, match="'start' must be three finite numbers"):
            env.reset(options={"start": bad})
    for bad in ([1, 2], "test_course", 3):
        with pytest.raises(ValueError, match="reset options: expected a dict"):
            env.reset(options=bad)


def test_a_refused_reset_leaves_no_episode_to_step_on():
    """After a reset that was refused, step() asks for a reset rather than going on with the episode before it."""
    from gymnasium.error import ResetNeeded

    env = OffRoadNavEnv(_scenario(), image_size=SMALL)
    env.reset(seed=0)
    env.step(10)
    for bad in ({"start": (1.0, float("nan"), 0.0)}, {"start": (500.0, 1.0, 0.0)}, {"course": "x"}):
        with pytest.raises(ValueError):
            env.reset(options=bad)
        with pytest.raises(ResetNeeded, match="call reset"):
            env.step(10)
    _, info = env.reset(seed=0)
    assert set(info["reward_terms"]) == set(env.step(10)[4]["reward_terms"])  # the same terms at a reset as at a step


def test_render_modes():
    with pytest.raises(ValueError, match="render_mode"):
        OffRoadNavEnv(_scenario(), render_mode="bogus")
    assert _env().render() is None
    env = _env(render_mode="rgb_array")
    env.reset(seed=0)
    rgb = env.render()
    assert rgb.shape == (480, 1120, 3) and rgb.dtype == np.uint8
    np.testing.assert_array_equal(rgb[:, 480:], env.classes.palette()[env.sim.frame().image])  # the camera, right
    top = rgb[:, :480]
    assert (top[240, 232] == 0).all()  # the vehicle at the centre of the top-down view, facing east
    assert (top == 255).all(axis=-1).sum() > 100  # the path


def test_the_options_are_one_config_and_each_is_also_a_keyword():
    config = EnvConfig(image_size=SMALL, n_waypoints=3)
    by_config, by_keywords = OffRoadNavEnv(_scenario(), config), OffRoadNavEnv(_scenario(), image_size=SMALL, n_waypoints=3)
    assert by_config.config == by_keywords.config and by_config.observation_space == by_keywords.observation_space
    assert OffRoadNavEnv(_scenario(), config, n_waypoints=5).config == EnvConfig(image_size=SMALL, n_waypoints=5)  # a keyword wins
    with pytest.raises(TypeError):
        OffRoadNavEnv(_scenario(), bogus=1)


def test_bad_construction_arguments():
    for kwargs in (
        {"action_type": "joystick"},
        {"image_encoding": "rgb"},
        {"image_size": (481, 640)},
        {"scenario": []},
        {"n_waypoints": 0},
    ):
        with pytest.raises(ValueError):
            OffRoadNavEnv(**{"scenario": _scenario(), **kwargs})
    with pytest.raises(ValueError, match="finite"):
        RewardConfig(goal_reward=float("nan"))
    for size in ((10.5, 20), "abc", (0, 5), (48,), (True, 64)):  # never truncated to whole pixels, nor read as digits
        with pytest.raises(ValueError, match="image_size must be None or two whole numbers"):
            OffRoadNavEnv(_scenario(), image_size=size)


# --- the clients people use --------------------------------------------------------------------


def test_a_gymnasium_vector_env_mixes_courses():
    envs = gym.vector.SyncVectorEnv(
        [lambda name=name: gym.make(ENV_ID, scenario=name, image_size=SMALL) for name in ("demo_course", "test_course")]
    )
    obs, info = envs.reset(seed=0)
    assert obs["image"].shape == (2, *SMALL, 1) and list(info["scenario"]) == ["demo_course", "test_course"]
    for _ in range(12):  # the field UGV reaches 1 m/s after 1 s at 1 m/s^2; then 0.1 m of progress a frame
        obs, reward, terminated, truncated, info = envs.step(np.array([10, 10]))
    np.testing.assert_allclose(reward, 0.1, atol=0.02)
    envs.close()


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_sb3_ppo_trains_on_two_courses_through_make_vec_env(tmp_path, monkeypatch):
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path))  # its logger's folder: not a new one in the system's temporary folder
    courses = iter(["demo_course", "fig8_water_mud_rock_mud_left"])
    venv = make_vec_env(lambda: gym.make(ENV_ID, scenario=next(courses), image_size=SMALL, image_encoding="onehot"), n_envs=2, seed=0)
    assert [e.unwrapped.sim.scenario.name for e in venv.envs] == ["demo_course", "fig8_water_mud_rock_mud_left"]
    model = PPO("MultiInputPolicy", venv, n_steps=16, batch_size=16, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=32)
    assert model.num_timesteps == 32
    action, _ = model.predict(venv.reset(), deterministic=True)
    assert action.shape == (2,) and all(0 <= a < 21 for a in action)


# --- what a review found -------------------------------------------------------------------------


def test_progress_resumes_after_a_detour_outside_the_path_band():
    env = gym.make(ENV_ID, scenario="demo_course", image_size=SMALL, start_jitter_m=0.0, start_yaw_jitter_rad=0.0).unwrapped
    env.reset(options={"start": (2.0, 16.0, 0.0)})  # 6 m left of the path, driving along it
    credited = 0.0
    for a in [10] * 200 + [0] * 15 + [10] * 45 + [20] * 15 + [10] * 80:
        obs, _, terminated, _, info = env.step(a)
        credited += info["reward_terms"]["progress"]
        if terminated:
            break
    s_true, offset = env.sim.path.project(np.array(env.sim.vehicle.pose[:2]))
    assert info["path_position_m"] == pytest.approx(s_true, abs=0.05)  # followed even outside the path band
    assert info["progress_m"] == pytest.approx(credited, abs=1e-9)  # what the reward credited
    assert abs(obs["pose"][0] - offset) < 0.05 and obs["waypoints"][0] > 0.0  # the path ahead, not behind
    assert 0.0 < credited < s_true - 2.0  # the stretch driven outside the path band earned nothing


def test_a_start_anywhere_along_the_path():
    env = gym.make(ENV_ID, scenario="test_course", image_size=SMALL).unwrapped
    path = env.sim.path
    x, y = path.point_at(100.0)
    obs, info = env.reset(options={"start": (x, y, float(path.heading_at(100.0)))})
    assert info["progress_m"] == pytest.approx(100.0, abs=1e-6) and abs(obs["pose"][0]) < 1e-6
    for _ in range(30):
        _, _, _, _, info = env.step(10)
    assert info["progress_m"] > 102.0
    with pytest.raises(ValueError, match="off the"):
        env.reset(options={"start": (-50.0, -50.0, 0.0)})


def test_a_jittered_start_is_drawn_again_where_it_would_touch_lethal_terrain_or_leave_the_map():
    # Trees from 1 m left of the start (y 6-8): the footprint, 0.6 m each side, reaches them when
    # the jitter moves the start more than 0.4 m left; the start itself is clear. A path that starts
    # 0.1 m from the map's western edge: a draw more than 0.1 m west falls off the map.
    trees = {"class": "non_traversable", "rectangle": {"center": [3.0, 7.0], "size": [6.0, 2.0]}}
    near_trees = _scenario([trees], size=(40.0, 10.0), waypoints=[[2.0, 5.0], [38.0, 5.0]])
    near_edge = _scenario(size=(40.0, 10.0), waypoints=[[0.1, 5.0], [38.0, 5.0]])
    for scenario in (near_trees, near_edge):
        env = _env(scenario, start_jitter_m=0.5, start_yaw_jitter_rad=0.1, image_size=SMALL)
        for seed in range(40):
            env.reset(seed=seed)
            x, y, _ = env.sim.vehicle.pose
            assert not env.sim.started_in_contact and 0.0 <= x <= 40.0 and 0.0 <= y <= 10.0
            assert abs(x - scenario.start[0]) <= 0.5 and abs(y - scenario.start[1]) <= 0.5


def test_the_off_map_penalty_is_charged_once_per_exit():
    env = _env(terminate_off_map=False)
    env.reset(options={"start": (1.0, 5.0, math.pi)})  # 1 m from the western edge, facing it
    penalties = [env.step(10)[4]["reward_terms"]["off_map"] for _ in range(30)]
    assert penalties.count(-10.0) == 1 and sum(penalties) == -10.0


def test_reset_options_draw_a_generated_course():
    env = gym.make(ENV_ID, scenario="demo_course", image_size=SMALL)
    assert env.reset(seed=0, options={"scenario": "gen:*"})[1]["scenario"].startswith("gen:")
    with pytest.raises(ValueError, match="course name or a Scenario"):
        env.reset(options={"scenario": ["demo_course"]})


def test_on_relief_a_tip_or_a_time_stuck_ends_the_episode_as_an_entry_onto_lethal_terrain_does():
    """relief_hazards: driving straight at its ledge, the vehicle is held by a step too high; driving
    along its bank's slope, it tips; each ends the episode with the collision's price. A start
    that puts the body past its roll limit is refused, as one on lethal terrain is."""
    env = OffRoadNavEnv("relief_hazards", image_size=SMALL)
    env.reset(seed=0)
    for _ in range(400):
        _, reward, terminated, truncated, info = env.step(10)  # straight on
        if terminated or truncated:
            break
    assert terminated and info["stuck"] == 1 and info["tips"] == 0 and info["reward_terms"]["collision"] == -10.0
    env.reset(seed=0, options={"start": (33.0, 14.0, 0.0)})  # beside the bank, on its slope
    for _ in range(100):
        _, reward, terminated, truncated, info = env.step(10)
        if terminated or truncated:
            break
    assert terminated and info["tips"] == 1 and info["reward_terms"]["collision"] == -10.0
    with pytest.raises(ValueError, match="past its roll or pitch limit"):
        env.reset(options={"start": (40.0, 12.4, 0.0)})
