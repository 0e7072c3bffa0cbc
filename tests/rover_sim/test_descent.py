"""The DIMES descent scenario: scripted kinematics, sensors, the kilometre-scale terrain, and rendering.

Rendering tests (``render`` marker) share one EGL context per world; the integration test flies one full descent
over a lighter plain (60 craters, 1024 px texture) and runs DIMES on it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import rover_sim  # noqa: F401  (first: sets MUJOCO_GL=egl before anything imports mujoco)
from nav.dimes import estimate_velocity
from nav.geometry import so3_log
from rover_sim.apps.descent import (
    FEATURELESS_TERRAIN,
    IMAGE_ALTITUDES_M,
    DescentConditions,
    DescentTerrainSpec,
    DescentTrajectory,
    DescentWorld,
    crater_population,
    descent_recipe,
    descent_terrain,
    ground_footprint_m,
    imu_accel_error_mps2,
    simulate_descent,
    with_wind,
)
from rover_sim.apps.descent_scene import DescentCameraConfig, DescentRenderer
from rover_sim.sim.assembly import Sun
from terrains import Terrain

FLAT_PLAIN = Terrain.from_heights(np.zeros((801, 801)), 4.0)  # 3.2 km at 4 m, for sensor and geometry tests
LIGHT_SPEC = DescentTerrainSpec(crater_count=60, texture_px=1024)


class _StubRenderer:
    """Stands in for :class:`DescentRenderer` where only the sensor data matter (no GL)."""

    config = DescentCameraConfig()

    def render(self, T_world_cam, sun, noise=None) -> np.ndarray:
        return np.zeros((256, 256), np.uint8)


# ------------------------------------------------------------------------------------- conditions, motion


def test_conditions_are_seeded_and_within_the_issue_ranges():
    a, b = DescentConditions.sample(5), DescentConditions.sample(5)
    np.testing.assert_array_equal(a.wind_mps, b.wind_mps)
    assert a.noise_seed == b.noise_seed
    winds = [np.linalg.norm(DescentConditions.sample(s).wind_mps) for s in range(200)]
    assert max(winds) <= 20.0 and max(winds) > 18.0 and min(winds) < 2.0
    assert np.linalg.norm(DescentConditions.sample(3, max_wind_mps=5.0).wind_mps) <= 5.0


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_trajectory_descends_75_m_s_drifts_with_the_wind_and_swings_a_few_degrees(seed):
    c = DescentConditions.sample(seed)
    traj = DescentTrajectory(c)
    times = traj.image_times_s
    assert np.all(np.abs(np.diff(times) - 4.0) < 0.35)  # about 4 s apart at 70-80 m/s
    for t, h in zip(times, IMAGE_ALTITUDES_M, strict=True):
        assert abs(traj.position_m(t)[2] - h) < 1.0
        v = traj.velocity_mps(t)
        assert abs(-v[2] - c.descent_rate_mps) < 0.5
        # wind + shear-driven change + swing velocity
        assert np.linalg.norm(v[:2] - c.wind_mps) < 0.4 * 8 + 2.5
        tilt = math.degrees(math.acos(traj.R_world_body(t)[2, 2]))
        assert tilt <= 5.0 + 1e-9
        rate = np.degrees(np.linalg.norm(so3_log(traj.R_world_body(t).T @ traj.R_world_body(t + 0.01)))) / 0.01
        assert rate < 6.0  # "rates of a few deg/s"
    # the camera looks down along body -z
    np.testing.assert_allclose(traj.R_world_cam(0.0)[:, 2], -traj.R_world_body(0.0)[:, 2])


def test_sensor_data_carry_only_the_modelled_errors():
    c = DescentConditions.sample(11)
    run = simulate_descent(c, FLAT_PLAIN, _StubRenderer())
    truth = run.truth
    acc_err = imu_accel_error_mps2(c)
    assert np.linalg.norm(acc_err[:2]) < 0.03
    for k, f in enumerate(run.frames):
        t = f.t_s - run.frames[0].t_s
        np.testing.assert_allclose(f.imu_delta_v_mps, truth.velocities_mps[k] - truth.velocities_mps[0] + acc_err * t)
        att_err = np.degrees(np.linalg.norm(so3_log(f.R_world_cam @ truth.R_world_cam[k].T)))
        assert att_err < 0.6
        assert abs(f.altitude_m - truth.altitudes_agl_m[k]) < 5 * c.radar_noise_m + 0.01 * truth.altitudes_agl_m[k]
        assert f.image.shape == (256, 256)
    np.testing.assert_allclose(truth.horizontal_velocity_mps, truth.velocities_mps[2, :2])


def test_a_view_beyond_the_patch_is_an_error():
    small = Terrain.from_heights(np.zeros((301, 301)), 4.0)  # 1.2 km: smaller than the view from 2000 m
    with pytest.raises(ValueError, match="beyond"):
        simulate_descent(DescentConditions.sample(0), small, _StubRenderer())


# ------------------------------------------------------------------------------------------------ terrain


def test_recipe_is_the_plain_at_reduced_scale():
    spec = DescentTerrainSpec()
    assert spec.recipe_scale == 2.0
    recipe = descent_recipe(spec, 3)
    assert recipe.size_m == (1600.0, 1600.0) and recipe.cell_size_m == 2.0
    craters = crater_population(spec, 3)
    d = np.array([c[2] for c in craters])
    assert len(craters) == 150 and d.min() >= 20.0 and d.max() <= 500.0
    assert 0.01 < np.mean(d > 100.0) < 0.1  # N(>D) ~ D^-2: (20/100)^2 = 4 %
    np.testing.assert_allclose(sorted(c.diameter_m * 2.0 for c in recipe.craters), np.sort(d))


def test_scaled_terrain_keeps_crater_geometry():
    """Synthesised at half scale and scaled up: a crater's depth is that of the full-scale crater."""
    spec = DescentTerrainSpec(size_m=1200.0, crater_count=3, crater_diameter_m=(150.0, 300.0), roughness_rms_m=0.01)
    terrain = descent_terrain(spec, 2)
    assert terrain.cell_size_m == 4.0 and terrain.half_x_m == 600.0
    x, y, d, dd, rim = max(crater_population(spec, 2), key=lambda c: c[2])
    floor = float(terrain.height_at(x, y))
    expected = (rim - dd) * d  # rim-to-floor depth dd * D below a rim at rim * D
    assert abs(floor - expected) < 0.05 * dd * d + 1.0


# ---------------------------------------------------------------------------------------------- rendering


@pytest.fixture(scope="module")
def marker_renderer():
    """Flat 3.2 km plain, uniform grey, with one bright disc 20 m in radius at (350, -420)."""
    n = 1024
    xs = -1600.0 + (np.arange(n) + 0.5) * 3200.0 / n
    albedo = np.full((n, n), 0.35)
    albedo[(xs[None, :] - 350.0) ** 2 + (xs[:, None] + 420.0) ** 2 < 20.0**2] = 1.0
    rgb = np.rint(np.repeat(albedo[..., None], 3, axis=-1) * 255).astype(np.uint8)
    r = DescentRenderer(FLAT_PLAIN, rgb)
    yield r
    r.close()


def _pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


@pytest.mark.render
def test_rendered_marker_lands_where_the_camera_model_projects_it(marker_renderer):
    traj = DescentTrajectory(DescentConditions.sample(4))
    R = traj.R_world_cam(2.0)
    p = np.array([150.0, -250.0, 1700.0])
    cam = DescentCameraConfig().camera()
    img = marker_renderer.render(_pose(R, p), Sun(azimuth_deg=0.0, elevation_deg=90.0, shadows=False))
    assert img.min() > 20  # ground everywhere: no sky, nothing clipped at 1.7 km
    vv, uu = np.nonzero(img > 0.5 * (int(img.max()) + int(np.median(img))))
    expected = cam.project(((np.array([350.0, -420.0, 0.0]) - p) @ R)[None])[0]
    np.testing.assert_allclose([uu.mean(), vv.mean()], expected, atol=0.5)
    assert np.all(np.abs(ground_footprint_m(cam, R, p)) < 1600.0)


@pytest.mark.render
def test_rendering_is_deterministic(marker_renderer):
    from rover_sim.render.config import ImageNoise

    T = _pose(DescentTrajectory(DescentConditions.sample(1)).R_world_cam(0.0), np.array([0.0, 0.0, 2000.0]))
    sun = Sun(azimuth_deg=30.0, elevation_deg=50.0, shadows=False)
    a = marker_renderer.render(T, sun, ImageNoise(3.0, seed=9))
    b = marker_renderer.render(T, sun, ImageNoise(3.0, seed=9))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, marker_renderer.render(T, sun, ImageNoise(3.0, seed=10)))


@pytest.mark.render
def test_one_rendered_descent_gives_an_accurate_velocity_and_the_featureless_plain_none():
    with DescentWorld.build(5, LIGHT_SPEC) as world:
        conditions = with_wind(DescentConditions.sample(21), [12.0, -13.0])  # 17.7 m/s toward the south-east
        run = world.fly(conditions)
        again = world.fly(conditions)
    for a, b in zip(run.frames, again.frames, strict=True):
        np.testing.assert_array_equal(a.image, b.image)  # deterministic for a seed
    result = estimate_velocity(run.frames)
    assert result.valid, result.reason
    error = np.linalg.norm(result.velocity_mps - run.truth.horizontal_velocity_mps)
    assert error < 1.0, (result.velocity_mps, run.truth.horizontal_velocity_mps)
    assert np.linalg.norm(run.truth.horizontal_velocity_mps) > 15.0  # a real drift was measured
    assert result.fire_tirs

    with DescentWorld.build(5, FEATURELESS_TERRAIN) as flat_world:
        flat = estimate_velocity(flat_world.fly(DescentConditions.sample(21)).frames)
    assert not flat.valid and flat.velocity_mps is None and not flat.fire_tirs
