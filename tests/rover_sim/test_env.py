"""The Gymnasium environment (rover_sim/env.py): API conformance, honesty of the observation, determinism."""

from __future__ import annotations

import math

import gymnasium
import numpy as np
import pytest

import rover_sim  # noqa: F401  (first: MUJOCO_GL=egl, and registers rover_sim/MER-v0)
from rover_sim.env import RoverEnv

pytestmark = pytest.mark.render

START_X_M = -1.5
# a small flat world (6 m x 6 m, no rocks): about 1 s per reset; 64 px images keep the steps cheap
SMALL = {
    "scenario": "meridiani_plains",
    "overrides": ("terrain.size_m=[6, 6]", f"start.x_m={START_X_M}"),
    "resolution_px": 64,
    "max_steps": 10,
    "speed_m_s": 0.05,
    "imu_samples": 1024,
}
OBS_KEYS = {"navcam_left", "navcam_right", "imu", "imu_count", "encoders", "mast"}
TRUTH_KEYS = {"position_m", "quat_wxyz", "tilt_deg", "wheel_slip", "wheel_sinkage_m", "body_contacts", "rock_contacts"}
STRAIGHT_HALF_M = np.array([1.0, 0.0, 0.5], dtype=np.float32)  # drive 0.5 m straight


def test_registered_and_light_import():
    assert "rover_sim/MER-v0" in gymnasium.registry and "rover_sim/MERGoal-v0" in gymnasium.registry
    import subprocess
    import sys

    code = "import sys, rover_sim; assert 'mujoco' not in sys.modules and 'rover_sim.sim.physics' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_check_env():
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make("rover_sim/MER-v0", **SMALL)
    try:
        check_env(env.unwrapped)
    finally:
        env.close()


def test_no_truth_in_observation():
    env = RoverEnv(**SMALL)
    try:
        assert set(env.observation_space.spaces) == OBS_KEYS
        for key in env.observation_space.spaces:
            assert not any(w in key for w in ("pose", "position", "slip", "sinkage", "contact", "quat", "tilt"))
        obs, info = env.reset(seed=3)
        assert set(obs) == OBS_KEYS and obs in env.observation_space
        assert TRUTH_KEYS <= set(info)
        obs, _, _, _, info = env.step(STRAIGHT_HALF_M)
        assert TRUTH_KEYS | {"drive", "termination"} <= set(info)
        assert 0 < obs["imu_count"] <= 1024 and np.abs(obs["imu"][: obs["imu_count"], 5]).mean() > 3.0  # ~Mars g
    finally:
        env.close()


def test_goal_variant_observes_the_goal_in_the_start_frame():
    env = gymnasium.make("rover_sim/MERGoal-v0", **SMALL)
    try:
        obs, info = env.reset(seed=5)
        assert set(obs) == OBS_KEYS | {"goal"}
        goal = info["goal_xy"] - np.array([START_X_M, 0.0])  # start yaw 0: start frame = world axes
        np.testing.assert_allclose(obs["goal"], goal, atol=1e-5)
        assert np.hypot(*obs["goal"]) <= 5.0 + 1e-6 and np.abs(info["goal_xy"]).max() <= 2.0  # inside the patch
    finally:
        env.close()


def test_determinism_and_plausible_motion():
    actions = [STRAIGHT_HALF_M, np.array([-1.0, 0.0, 0.2], dtype=np.float32)]

    def run(env):
        obs, info = env.reset(seed=7)
        out = [(obs, info["position_m"])]
        for a in actions:
            obs, _, _, _, info = env.step(a)
            out.append((obs, info["position_m"]))
        return out

    env_a, env_b = RoverEnv(**SMALL), RoverEnv(**SMALL)
    try:
        a = run(env_a)
        env_b.reset(seed=8)  # a different world first, then rebuilt for seed 7
        b = run(env_b)
        c = run(env_b)  # the same world reused (placed again)
    finally:
        env_a.close()
        env_b.close()
    for (oa, pa), (ob, pb), (oc, pc) in zip(a, b, c, strict=True):
        for k in oa:
            np.testing.assert_array_equal(oa[k], ob[k], err_msg=k)
            np.testing.assert_array_equal(oa[k], oc[k], err_msg=k)
        np.testing.assert_array_equal(pa, pb)
        np.testing.assert_array_equal(pa, pc)
    moved = np.linalg.norm(a[1][1][:2] - a[0][1][:2])
    assert 0.35 < moved < 0.55, moved  # 0.5 m of wheel travel on flat sand: a little slip, no more
    assert not np.array_equal(a[0][0]["navcam_left"], a[1][0]["navcam_left"])  # the view changed


def test_goal_terminates():
    env = RoverEnv(**SMALL, goal=(START_X_M + 0.4, 0.0), goal_tolerance_m=0.15)
    try:
        _, info = env.reset(seed=1)
        assert math.isclose(info["goal_distance_m"], 0.4, abs_tol=0.05)
        _, reward, terminated, truncated, info = env.step(STRAIGHT_HALF_M)
        assert terminated and not truncated and info["termination"] == "goal"
        assert info["goal_distance_m"] <= 0.15 and not info["drive"]["completed"]  # stopped at the goal
        assert reward > env.reward_config.goal_bonus
    finally:
        env.close()


def test_truncation_and_divergence_end_cleanly(monkeypatch):
    from rover_sim.errors import PhysicsDiverged

    env = RoverEnv(**{**SMALL, "max_steps": 1})
    try:
        env.reset(seed=2)
        *_, terminated, truncated, _ = env.step(np.zeros(3, dtype=np.float32))
        assert truncated and not terminated
        env.reset(seed=2)

        def boom(*args, **kwargs):
            raise PhysicsDiverged(1.0, "test")

        monkeypatch.setattr("rover_sim.sim.drive.execute", boom)
        obs, _, terminated, truncated, info = env.step(STRAIGHT_HALF_M)
        assert terminated and info["termination"] == "physics_diverged" and obs in env.observation_space
    finally:
        env.close()
    env.close()  # closing twice is fine


def _make_small():
    import rover_sim.env  # noqa: F401  (registers in the spawned worker)

    return gymnasium.make("rover_sim/MER-v0", **SMALL)


def test_async_vector_env_spawn():
    envs = gymnasium.vector.AsyncVectorEnv([_make_small, _make_small], context="spawn")
    try:
        obs, info = envs.reset(seed=[0, 1])
        assert obs["navcam_left"].shape == (2, 64, 64) and obs["navcam_left"].dtype == np.uint8
        for _ in range(2):
            obs, reward, terminated, truncated, info = envs.step(np.tile(STRAIGHT_HALF_M * 0.5, (2, 1)))
        assert reward.shape == (2,) and obs["encoders"].shape == (2, 10)
        assert (obs["encoders"][:, :6] > 1.0).all()  # 0.5 m of rolling on a 0.125 m wheel: 2 rad
    finally:
        envs.close()


def test_keep_out_terminates_with_penalty():
    zone = f'keep_out=[{{name = "zone", x_m = {START_X_M + 0.6}, y_m = 0.0, radius_m = 0.3}}]'
    env = RoverEnv(**{**SMALL, "overrides": (*SMALL["overrides"], zone)}, goal=None)
    try:
        env.reset(seed=4)
        _, reward, terminated, _, info = env.step(STRAIGHT_HALF_M)
        assert terminated and info["termination"] == "keep_out" and reward == -env.reward_config.keep_out_penalty
        assert np.hypot(info["position_m"][0] - (START_X_M + 0.6), info["position_m"][1]) < 0.3
    finally:
        env.close()


def test_flight_images_are_the_missions_rectified_pairs():
    """Flight profile: the env's images are the mission chain's pairs (true lenses, CCD formation, onboard
    rectification through the calibrated models: World + Onboard.rectified) for the same world and noise seed."""
    from types import SimpleNamespace

    from rover_sim.runtime.onboard import Onboard
    from rover_sim.world.world import World

    # classic regolith: the env paints the world's soil as before (the texture is not the sensor chain)
    over = (*SMALL["overrides"], 'appearance.regolith="classic"', "nav.resolution_px=64")
    pairs = ("navcam", "hazcam_front")  # the hazcams' fisheye makes raw and rectified images far apart
    kwargs = {**SMALL, "overrides": over, "cameras": pairs, "fixed_terrain": True}
    flight = RoverEnv(**kwargs)
    ideal = RoverEnv(**{**kwargs, "overrides": (*over, 'sensors.profile="ideal"')})
    world = None
    try:
        assert flight.scenario.sensors.profile == "flight" and flight.scenario.sensors.lens.enabled
        obs, info = flight.reset(seed=11)
        obs_ideal, _ = ideal.reset(seed=11)
        assert obs in flight.observation_space and obs_ideal in ideal.observation_space
        for key in ("navcam_left", "hazcam_front_left"):
            diff = np.abs(obs[key].astype(int) - obs_ideal[key].astype(int)).mean()
            assert diff > 3.0, (key, diff)  # lens and calibration errors, vignetting, exposure, CCD noise
        world = World(flight.scenario)  # the scenario's seed is the env's world seed (fixed_terrain)
        np.testing.assert_array_equal(world.truth_pose().position_xyz_m, info["position_m"])  # same settled pose
        world.renderer.imaging.reseed_noise(info["image_noise_seed"])
        frames = {p: world.render(p) for p in pairs}  # in the env's order: the same noise draws
        observation = world.observation_with([], [], frames)
        onboard = Onboard(world.start_pose(), None, SimpleNamespace(), lambda: None)  # only its rectification
        for p in pairs:
            rectified = onboard.rectified(observation, p)
            np.testing.assert_array_equal(obs[f"{p}_left"], rectified.left_u8, err_msg=p)
            np.testing.assert_array_equal(obs[f"{p}_right"], rectified.right_u8, err_msg=p)
        raw_vs_rectified = np.abs(frames["hazcam_front"].left.astype(int) - obs["hazcam_front_left"]).mean()
        assert raw_vs_rectified > 5.0, raw_vs_rectified  # the env delivers the rectified pair, not the raw one
    finally:
        flight.close()
        ideal.close()
        if world is not None:
            world.close()


@pytest.mark.parametrize("bad", [[np.nan, 0.0, 0.5], [1.0, np.inf, 0.5], [1.0, 0.0]])
def test_a_nan_inf_or_misshaped_action_is_an_error_not_a_drive(bad):
    env = RoverEnv(**SMALL)
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError, match="3 finite numbers"):
            env.step(np.asarray(bad))
    finally:
        env.close()
