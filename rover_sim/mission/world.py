"""The world of one scenario: terrain, physics with the wheel-soil law, sensors and the offscreen renderer.

:class:`World` is what a user steps by hand (see the README's library guide) and what the pipeline drives. It
produces two kinds of output, kept apart: :meth:`World.observation` (sensor data only: what the onboard stack may
see) and :meth:`World.truth_pose` / :attr:`World.sim` (ground truth: for the evaluator, recorders and ``info``).

Mast convention (one everywhere): ``pan_deg`` left positive, ``elevation_deg`` up positive (the scenario's
``mast_tilt_deg`` is an elevation too; the tilt joint itself turns the other way, which only
:meth:`World.point_mast` knows).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from types import MappingProxyType

import numpy as np

from nav.camera import StereoRig
from nav.trajectory import Pose
from rover_sim.mission.observation import Observation, StereoImages
from rover_sim.mission.scenario import Scenario
from rover_sim.render.renderer import ImageNoise, RenderConfig, StereoFrame, StereoRenderer, terrain_texture
from rover_sim.sim.physics import RoverSim
from rover_sim.sim.sensors import SensorSuite
from rover_sim.sim.world import Sun
from rover_sim.sim.stream import TerrainStreamer
from terrains import Terrain, synthesize, texture_rgb_u8

MAX_TEXTURE_SIDE_PX = 8192  # ground texture memory stays under ~200 MB
SETTLE_S = 1.0  # the rover settles on the terrain before the run starts


def _window_painter(streamer: TerrainStreamer, px_per_m: float, contrast: float) -> Callable[[Terrain], np.ndarray]:
    """Texture of a streamed window from world-coordinate albedo, per tile (``StreamedSite.window_albedo``)."""
    return lambda window: texture_rgb_u8(streamer.site.window_albedo(window, px_per_m, contrast))


def texture_px_per_m(terrain: Terrain, wanted_px_per_m: float) -> float:
    side = 2.0 * max(terrain.half_x_m, terrain.half_y_m)
    return float(min(wanted_px_per_m, MAX_TEXTURE_SIDE_PX / side))


class World:
    """Terrain + physics + sensors + renderer for ``scenario``; the rover placed at its start and settled."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        ap = scenario.appearance
        streamer, texture, texture_fn = None, None, None
        if scenario.terrain.streamed is not None:  # large sites: a window of tiles follows the rover
            streamer = TerrainStreamer(scenario.terrain, scenario.seed)
            terrain = streamer.initial_window(scenario.start.x_m, scenario.start.y_m)
            texture_fn = _window_painter(streamer, texture_px_per_m(terrain, ap.texture_px_per_m), ap.contrast)
        else:
            terrain = synthesize(scenario.terrain, scenario.seed)
            texture = terrain_texture(
                terrain,
                texture_px_per_m(terrain, ap.texture_px_per_m),
                scenario.seed,
                fine_soil=ap.fine_soil,
                contrast=ap.contrast,
                patches=ap.patch_tuples(),
            )
        self.sim = RoverSim(
            terrain,
            Sun(scenario.sun.azimuth_deg, scenario.sun.elevation_deg, scenario.sun.shadows),
            texture_rgb=texture,
            timestep_s=scenario.physics.timestep_s,
            soil_model=scenario.physics.soil_model,
            streamer=streamer,
            texture_fn=texture_fn,
        )
        if scenario.physics.deformable:  # experimental, wong_reece only: ruts, berms, multipass (sim/deform.py)
            self.sim.enable_deformation()
        self.sim.lock_wheels(list(scenario.faults.locked_wheels))
        st = scenario.start
        self.sim.place(st.x_m, st.y_m, math.radians(st.yaw_deg))
        self.mast_pan_deg, self.mast_elevation_deg = 0.0, 0.0
        self.point_mast(scenario.nav.mast_pan_deg, scenario.nav.mast_tilt_deg)
        self.sim.step_for(SETTLE_S)
        self.sensors = SensorSuite(self.sim, seed=scenario.seed)  # samples the IMU inside the physics loop
        noise = ImageNoise(seed=scenario.seed) if scenario.nav.image_noise else None
        self.renderer = StereoRenderer(
            self.sim, RenderConfig(resolution_px=scenario.nav.resolution_px, noise=noise, shadows=scenario.sun.shadows)
        )
        self._rigs: dict[str, StereoRig] = {}
        self.calibrate(scenario.nav.camera)
        # the ephemeris: the sun's direction over the site (fixed over a drive of minutes)
        self.sun_direction_world = Sun(scenario.sun.azimuth_deg, scenario.sun.elevation_deg).direction()
        # the operator-given start of the drive (previous localisation and sun finding), fixed once settled
        self.operator_start_pose = Pose(self.sim.time_s, self.sim.position_m(), self.sim.quat_wxyz())

    @property
    def terrain(self) -> Terrain:
        """The terrain under the rover (for a streamed site: the current window)."""
        return self.sim.terrain

    # ------------------------------------------------------------------ commands to the hardware
    def point_mast(self, pan_deg: float, elevation_deg: float) -> None:
        """Command the mast (pan left positive, elevation up positive); the servos move as physics steps."""
        self.mast_pan_deg, self.mast_elevation_deg = pan_deg, elevation_deg
        self.sim.set_mast(math.radians(pan_deg), -math.radians(elevation_deg))

    def calibrate(self, camera: str) -> StereoRig:
        """The camera model flight software holds for ``camera``: the calibrated rig at the current (commanded)
        pointing, fixed until :meth:`calibrate` is called again after a repointing."""
        self._rigs[camera] = self.renderer.rig(camera)
        return self._rigs[camera]

    def onboard_rig(self, camera: str) -> StereoRig:
        return self._rigs[camera] if camera in self._rigs else self.calibrate(camera)

    # ------------------------------------------------------------------ sensor data (what the rover sees)
    def observation(self, cameras: tuple[str, ...] = ()) -> Observation:
        """IMU and encoder samples since the last call, plus a fresh stereo pair of each of ``cameras``."""
        imu, encoders = self.sensors.poll()
        return self.observation_with(imu, encoders, {c: self.render(c) for c in cameras})

    def render(self, camera: str) -> StereoFrame:
        return self.renderer.render_pair(camera)

    def observation_with(self, imu: list, encoders: list, frames: dict[str, StereoFrame]) -> Observation:
        """An Observation of given sensor samples and rendered frames; each pair carries the *onboard* rig."""
        images = {c: StereoImages(c, f.t_s, f.left, f.right, self.onboard_rig(c)) for c, f in frames.items()}
        return Observation(
            t_s=self.sim.time_s,
            imu=tuple(imu),
            encoders=tuple(encoders),
            images=MappingProxyType(images),
            mast_pan_deg=self.mast_pan_deg,
            mast_elevation_deg=self.mast_elevation_deg,
            start_pose=self.operator_start_pose,
            sun_direction_world=self.sun_direction_world,
        )

    # ------------------------------------------------------------------ ground truth (never onboard)
    def truth_pose(self) -> Pose:
        return Pose(self.sim.time_s, self.sim.position_m(), self.sim.quat_wxyz())

    def start_pose(self) -> Pose:
        """The operator-given start pose of the drive (from the previous localisation and sun finding)."""
        return self.operator_start_pose

    def close(self) -> None:
        self.sensors.detach()
        self.renderer.close()
