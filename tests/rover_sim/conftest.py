"""Shared, session-scoped worlds for the camera, render and sensor tests (built once per test session)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

import rover_sim  # noqa: F401  (first: sets MUJOCO_GL=egl before anything imports mujoco)
from rover_sim.render.cameras import camera_world_pose, stereo_rig
from rover_sim.sim.assembly import Sun
from rover_sim.sim.physics import RoverSim
from rover_sim.sim.sensors import point_mast
from terrains import (
    ExplicitRockSpec,
    RockSpec,
    SlopeSpec,
    Terrain,
    TerrainRecipe,
    albedo_texture,
    synthesize,
    texture_rgb_u8,
)

RENDER_POSE = (-2.5, -1.5, 0.4)  # x m, y m, yaw rad: not axis-aligned on purpose
RENDER_MAST = (0.25, 0.55)  # pan, tilt rad: pan non-zero so the mast kinematics matter
RENDER_PX_PER_M = 100.0
MARKER_RADIUS_M = 0.05
# Where the camera-geometry markers are painted: the ground seen by these pixels of these cameras.
MARKER_PIXELS = {"hazcam_front_left": (40.0, 112.0), "navcam_left": (70.0, 120.0)}
RAY_GROUPS = np.array([1, 1, 1, 0, 0, 0], dtype=np.uint8)  # terrain/rocks (0), rover visuals (2); not collision (3)


def render_terrain() -> Terrain:
    recipe = TerrainRecipe(
        size_m=(12.0, 12.0),
        cell_size_m=0.05,
        slope=SlopeSpec(slope_deg=6.0, azimuth_deg=60.0),
        rocks=RockSpec(cover_fraction=0.0),
        explicit_rocks=[
            ExplicitRockSpec(name="block", x_m=1.2, y_m=1.0, length_m=0.6, width_m=0.45, height_m=0.3, yaw_deg=20)
        ],
    )
    return synthesize(recipe, seed=11)


def ray_to_scene(model, data, origin: np.ndarray, direction: np.ndarray) -> float:
    """Distance along unit ``direction`` to the first rendered geom (``inf`` if none)."""
    import mujoco

    geomid = np.full(1, -1, dtype=np.int32)
    d = mujoco.mj_ray(model, data, origin, direction, RAY_GROUPS, 1, -1, geomid)
    return math.inf if d < 0 else float(d)


def pixel_ray_world(model, data, cam_name: str, cam, uv) -> tuple:
    T = camera_world_pose(model, data, cam_name)
    return T[:3, 3].copy(), T[:3, :3] @ cam.ray(np.asarray(uv, dtype=float))[0]


@dataclass
class MarkedWorld:
    sim: RoverSim
    markers_xyz: dict[str, np.ndarray]  # world position of each painted marker (on the rendered surface)
    texture_rgb: np.ndarray


def _placed_sim(terrain: Terrain, texture_rgb: np.ndarray | None) -> RoverSim:
    yaw = RENDER_POSE[2]
    sun = Sun(azimuth_deg=math.degrees(yaw) + 180.0, elevation_deg=35.0)  # behind the rover: shadow ahead
    sim = RoverSim(terrain, sun=sun, texture_rgb=texture_rgb)
    sim.place(*RENDER_POSE)
    point_mast(sim, *RENDER_MAST)
    return sim


@pytest.fixture(scope="session")
def render_world() -> MarkedWorld:
    """Textured world (low-contrast soil, bright marker discs at known places), rover parked, sun behind it."""
    terrain = render_terrain()
    probe = _placed_sim(terrain, None)  # same placement: find where the markers must go
    markers = {}
    for cam_name, uv in MARKER_PIXELS.items():
        cam = stereo_rig(probe.model, probe.data, cam_name.removesuffix("_left"), 256).left
        origin, direction = pixel_ray_world(probe.model, probe.data, cam_name, cam, uv)
        dist = ray_to_scene(probe.model, probe.data, origin, direction)
        assert math.isfinite(dist), f"no ground under marker pixel of {cam_name}"
        markers[cam_name] = origin + dist * direction
    albedo = albedo_texture(terrain, RENDER_PX_PER_M, seed=5, contrast=0.3)
    h, w = albedo.shape
    xs = -terrain.half_x_m + (np.arange(w) + 0.5) * (2.0 * terrain.half_x_m / w)
    ys = -terrain.half_y_m + (np.arange(h) + 0.5) * (2.0 * terrain.half_y_m / h)
    for p in markers.values():
        albedo[(xs[None, :] - p[0]) ** 2 + (ys[:, None] - p[1]) ** 2 < MARKER_RADIUS_M**2] = 1.0
    rgb = texture_rgb_u8(albedo)
    sim = _placed_sim(terrain, rgb)
    np.testing.assert_allclose(sim.position_m(), probe.position_m(), atol=1e-9)  # texture never moves physics
    return MarkedWorld(sim, markers, rgb)


@pytest.fixture(scope="session")
def render_renderer(render_world):
    """The default navigation renderer (direct 256x256, shadows) on the shared world."""
    from rover_sim.render.renderer import StereoRenderer

    r = StereoRenderer(render_world.sim)
    yield r
    r.close()


@pytest.fixture(scope="session")
def sensor_slope_sim() -> RoverSim:
    """Rover parked across a 15 deg slope (untextured, no rendering)."""
    terrain = synthesize(
        TerrainRecipe(
            size_m=(8.0, 8.0), slope=SlopeSpec(slope_deg=15.0, azimuth_deg=30.0), rocks=RockSpec(cover_fraction=0.0)
        ),
        seed=2,
    )
    sim = RoverSim(terrain)
    sim.place(0.0, 0.0, 1.2, settle_s=3.0)
    return sim
