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
from types import MappingProxyType

import numpy as np

from nav.camera import StereoRig
from nav.geometry import R_to_quat_wxyz
from nav.rectify import StereoCalibration
from nav.trajectory import Pose
from rover_sim.render.cameras import camera_world_pose
from rover_sim.render.config import ImageNoise, RenderConfig
from rover_sim.render.renderer import StereoFrame, StereoRenderer, terrain_texture
from rover_sim.scenario.schema import Scenario
from rover_sim.sim.assembly import Sun
from rover_sim.sim.physics import RoverSim
from rover_sim.sim.sensors import OdometryErrors, SensorSuite
from rover_sim.sim.stream import TerrainStreamer
from rover_sim.world.calibration import MastEncoders, RunCalibration, build_true_lens, onboard_stereo_models
from rover_sim.world.clock import IMAGE_PAIR_ACQUIRE_S, Activity, MissionClock
from rover_sim.world.observation import Observation, StereoImages
from terrains import Terrain, synthesize, texture_rgb_u8

MAX_TEXTURE_SIDE_PX = 8192  # ground texture memory stays under ~200 MB
RELIEF_REBAKE_DEG = 3.0  # re-shade the soil's micro-relief when the sun has moved more than this (12 min of sun)
SETTLE_S = 1.0  # the rover settles on the terrain before the run starts
VIEW_SAMPLES = 16  # textured_view_fraction: a 16 x 16 grid of pixel rays
VIEW_MAX_RANGE_M, VIEW_RAY_STEP_M = 30.0, 0.05  # ... marched this far along each ray in steps of this


class WindowPainter:
    """Texture of a streamed window, per tile (``StreamedSite.window_albedo``): the multiscale regolith (as a whole
    site's, ``fine_soil`` and patches aside) with its relief shaded for :attr:`sun_direction`, or the classic
    albedo. :meth:`World.move_sun` updates the sun; windows painted from then on (each re-centre) use it."""

    def __init__(self, streamer: TerrainStreamer, px_per_m: float, contrast: float, multiscale: bool,
                 sun_direction: np.ndarray) -> None:  # fmt: skip
        self.streamer, self.px_per_m, self.contrast, self.multiscale = streamer, px_per_m, contrast, multiscale
        self.sun_direction = sun_direction

    def __call__(self, window: Terrain) -> np.ndarray:
        sun = self.sun_direction if self.multiscale else None
        albedo = self.streamer.site.window_albedo(
            window,
            self.px_per_m,
            self.contrast,
            multiscale=self.multiscale,
            sun_direction=sun,  # type: ignore[arg-type]
        )
        return texture_rgb_u8(albedo)


def perturbation(size: float, perturb_seed: int, scenario_seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A displacement of ``size`` metres and a rotation vector of ``size`` radians, in directions drawn from
    (``perturb_seed``, ``scenario_seed``): each seed of a scenario gets its own butterfly."""
    rng = np.random.default_rng([perturb_seed, scenario_seed])
    directions = rng.normal(size=(2, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return size * directions[0], size * directions[1]


def texture_px_per_m(terrain: Terrain, wanted_px_per_m: float) -> float:
    side = 2.0 * max(terrain.half_x_m, terrain.half_y_m)
    return float(min(wanted_px_per_m, MAX_TEXTURE_SIDE_PX / side))


def with_heading_error(pose: Pose, heading_error_rad: float) -> Pose:
    """``pose`` turned by ``heading_error_rad`` about the site vertical (a sun-finding heading error); the
    position, roll and pitch relative to the vertical are kept. Zero: ``pose`` itself."""
    if heading_error_rad == 0.0:
        return pose
    c, s = math.cos(heading_error_rad), math.sin(heading_error_rad)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Pose(pose.t_s, pose.position_xyz_m, R_to_quat_wxyz(Rz @ pose.R_world_rover))


def ground_texture(scenario: Scenario, terrain: Terrain, sun_direction: np.ndarray) -> np.ndarray:
    """The ground's RGB texture of a whole-site terrain (multiscale regolith: micro-relief shaded for
    ``sun_direction``)."""
    ap = scenario.appearance
    return terrain_texture(
        terrain,
        texture_px_per_m(terrain, ap.texture_px_per_m),
        scenario.seed,
        fine_soil=ap.fine_soil,
        contrast=ap.contrast,
        patches=ap.patch_tuples(),
        regolith=ap.regolith,
        sun_direction=sun_direction if ap.regolith == "multiscale" else None,
    )


class World:
    """Terrain + physics + sensors + renderer for ``scenario``; the rover placed at its start and settled."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        ap = scenario.appearance
        # the mission clock: with a moving sun or a sol's time budget
        lst = scenario.sun.local_solar_time_h
        start_h = lst if lst is not None else (scenario.sol.start_local_solar_time_h if scenario.sol else None)
        self.clock = MissionClock(start_h) if start_h is not None else None
        sun_az_deg, sun_el_deg = scenario.sun.azimuth_elevation_at(lst)
        self._baked_sun = Sun(sun_az_deg, sun_el_deg).direction()  # the sun the soil's micro-relief is shaded for
        self.streamer, texture, self._painter = None, None, None
        if scenario.terrain.streamed is not None:  # large sites: a window of tiles follows the rover
            self.streamer = TerrainStreamer(scenario.terrain, scenario.seed)
            terrain = self.streamer.initial_window(scenario.start.x_m, scenario.start.y_m)
            self._painter = WindowPainter(self.streamer, texture_px_per_m(terrain, ap.texture_px_per_m), ap.contrast,
                                          ap.regolith == "multiscale", self._baked_sun)  # fmt: skip
        else:
            terrain = synthesize(scenario.terrain, scenario.seed)
            texture = ground_texture(scenario, terrain, self._baked_sun)
        self.sim = RoverSim(
            terrain,
            Sun(sun_az_deg, sun_el_deg, scenario.sun.shadows),
            texture_rgb=texture,
            timestep_s=scenario.physics.timestep_s,
            soil_model=scenario.physics.soil_model,
            streamer=self.streamer,
            texture_fn=self._painter,
        )
        if scenario.physics.deformable:  # opt-in, wong_reece only: ruts, berms, multipass (sim/deform.py)
            self.sim.enable_deformation()
        self.sim.lock_wheels(list(scenario.faults.locked_wheels))
        st = scenario.start
        self.sim.place(st.x_m, st.y_m, math.radians(st.yaw_deg))
        lens = scenario.sensors.lens
        # [sensors.lens]: true mounting + calibration errors (None: ideal cameras), mast encoder errors
        self.calibration = RunCalibration(lens, scenario.seed) if lens.enabled else None
        self.mast_encoders = MastEncoders(lens, scenario.seed)
        self.mast_pan_deg, self.mast_elevation_deg = 0.0, 0.0
        self.point_mast(scenario.nav.mast_pan_deg, scenario.nav.mast_tilt_deg)
        self.sim.step_for(SETTLE_S)
        if scenario.physics.perturb_size > 0.0:
            self.sim.nudge(*perturbation(scenario.physics.perturb_size, scenario.physics.perturb_seed, scenario.seed))
        # [sensors.odometry]: this run's draw of the odometry and attitude errors (none in the ideal profile)
        odo = scenario.sensors.odometry
        self.odometry_errors = OdometryErrors.draw(scenario.seed, **odo.drawn_sizes())
        if odo.sinkage_rolling_radius and hasattr(self.sim.law, "sinkage_rolling_radius"):  # the Bekker law
            self.sim.law.sinkage_rolling_radius = True
        self.sensors = SensorSuite(self.sim, seed=scenario.seed, errors=self.odometry_errors)  # IMU in the loop
        noise = ImageNoise(seed=scenario.seed) if scenario.nav.image_noise else None
        config = RenderConfig(
            resolution_px=scenario.nav.resolution_px,
            noise=noise,
            shadows=scenario.sun.shadows,
            imaging=scenario.sensors.imaging,
            imaging_seed=scenario.seed,
        )
        true_lens = None
        if self.calibration is not None:
            true_lens = build_true_lens(self.sim.model, self.sim.data, self.calibration, config.native_px)
        self.renderer = StereoRenderer(self.sim, config, lens=true_lens)
        self._rigs: dict[str, StereoRig] = {}
        self._calibrations: dict[str, StereoCalibration | None] = {}
        self.calibrate(scenario.nav.camera)
        # the ephemeris: the sun's direction over the site (fixed over a drive of minutes)
        # (moves with the mission clock when the scenario sets local_solar_time_h)
        self.sun_direction_world = Sun(sun_az_deg, sun_el_deg).direction()
        self._clock_sim_s = self.sim.time_s
        # the operator-given start of the drive (previous localisation and sun finding), fixed once settled
        self.operator_start_pose = with_heading_error(
            Pose(self.sim.time_s, self.sim.position_m(), self.sim.quat_wxyz()), self.odometry_errors.heading_error_rad
        )

    @property
    def terrain(self) -> Terrain:
        """The terrain under the rover (for a streamed site: the current window)."""
        return self.sim.terrain

    # ------------------------------------------------------------------ commands to the hardware
    def point_mast(self, pan_deg: float, elevation_deg: float) -> None:
        """Command the mast (pan left positive, elevation up positive); the servos move as physics steps."""
        self.mast_pan_deg, self.mast_elevation_deg = pan_deg, elevation_deg
        pan_true_deg, elevation_true_deg = self.mast_encoders.true_angles_deg(pan_deg, elevation_deg)
        self.sim.set_mast(math.radians(pan_true_deg), -math.radians(elevation_true_deg))

    def calibrate(self, camera: str) -> StereoRig:
        """The camera model flight software holds for ``camera``: the calibrated rig at the current (commanded)
        pointing, fixed until :meth:`calibrate` is called again after a repointing.

        With ``[sensors.lens]`` errors: the rig is the *rectified* rig of the calibrated (erroneous) models at the
        commanded mast angles (:mod:`rover_sim.world.calibration`, :mod:`nav.rectify`), and the models travel
        with each pair for the onboard rectification."""
        spec = self.scenario.sensors.lens
        if self.calibration is None and not spec.has_mast_error:  # ideal: the exact rig at the current state
            self._rigs[camera], self._calibrations[camera] = self.renderer.rig(camera), None
            return self._rigs[camera]
        self._rigs[camera], self._calibrations[camera] = onboard_stereo_models(
            self.sim.model, self.sim.data, self.calibration, camera, self.renderer.config.resolution_px,
            self.mast_pan_deg, self.mast_elevation_deg,
        )  # fmt: skip
        return self._rigs[camera]

    def onboard_rig(self, camera: str) -> StereoRig:
        return self._rigs[camera] if camera in self._rigs else self.calibrate(camera)

    # ------------------------------------------------------------------ sensor data (what the rover sees)
    def observation(self, cameras: tuple[str, ...] = ()) -> Observation:
        """IMU and encoder samples since the last call, plus a fresh stereo pair of each of ``cameras``."""
        imu, encoders = self.sensors.poll()
        return self.observation_with(imu, encoders, {c: self.render(c) for c in cameras})

    def render(self, camera: str) -> StereoFrame:
        """Take a stereo pair; with a mission clock, the sun is first moved to the time of day of the pair."""
        if self.clock is not None:
            self.sync_clock()
            if self.scenario.sun.local_solar_time_h is not None:
                self.move_sun()
            self.clock.charge("imaging", IMAGE_PAIR_ACQUIRE_S)
        return self.renderer.render_pair(camera)

    def sync_clock(self) -> None:
        """Charge the physics time driven since the last sync as driving (no-op without a clock)."""
        if self.clock is not None:
            self.clock.charge("driving", max(self.sim.time_s - self._clock_sim_s, 0.0))
            self._clock_sim_s = self.sim.time_s

    # ------------------------------------------------------------------ time of day (mission clock)
    def charge(self, activity: Activity, seconds: float) -> None:
        """Account ``seconds`` of ``activity`` on the mission clock (no-op without one)."""
        if self.clock is not None:
            self.clock.charge(activity, seconds)

    def move_sun(self) -> None:
        """Point the renderer's sun and the ephemeris direction at the clock's local solar time."""
        assert self.clock is not None
        az, el = self.scenario.sun.azimuth_elevation_at(self.clock.local_solar_time_h)
        self.sun_direction_world = Sun(az, el).direction()
        self.renderer.set_sun(self.sun_direction_world)
        moved_deg = math.degrees(math.acos(min(1.0, float(self._baked_sun @ self.sun_direction_world))))
        if self.scenario.appearance.regolith == "multiscale" and moved_deg > RELIEF_REBAKE_DEG:
            self._baked_sun = self.sun_direction_world
            if self._painter is not None:  # streamed: the next windows (a re-centre per tile) are shaded anew
                self._painter.sun_direction = self._baked_sun
            else:
                self.renderer.set_ground_texture(ground_texture(self.scenario, self.terrain, self._baked_sun))

    def clock_summary(self) -> dict | None:
        """The mission clock for metrics.json (None without one); driving charged up to now."""
        if self.clock is None:
            return None
        self.sync_clock()
        return self.clock.summary()

    def observation_with(self, imu: list, encoders: list, frames: dict[str, StereoFrame]) -> Observation:
        """An Observation of given sensor samples and rendered frames; each pair carries the *onboard* rig."""
        images = {
            c: StereoImages(c, f.t_s, f.left, f.right, self.onboard_rig(c), self._calibrations.get(c))
            for c, f in frames.items()
        }
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

    def ground_view_xy_m(self, camera: str) -> np.ndarray:
        """Truth, for the evaluator: (N, 2) world xy where a ``VIEW_SAMPLES`` x ``VIEW_SAMPLES`` grid of pixel rays
        of the left camera of ``camera``'s pair (pinhole, at its true pose now) first meets the ground heightfield
        (rocks ignored), marched ``VIEW_RAY_STEP_M`` at a time; rays meeting no ground within
        ``VIEW_MAX_RANGE_M`` (sky, far field) are left out."""
        name = f"{camera}_left"
        cam = self.renderer.camera(name)
        T = camera_world_pose(self.sim.model, self.sim.data, name)
        u = (np.arange(VIEW_SAMPLES) + 0.5) * cam.width_px / VIEW_SAMPLES
        v = (np.arange(VIEW_SAMPLES) + 0.5) * cam.height_px / VIEW_SAMPLES
        rays = cam.ray(np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)) @ T[:3, :3].T
        t = np.arange(VIEW_RAY_STEP_M, VIEW_MAX_RANGE_M, VIEW_RAY_STEP_M)
        pts = T[:3, 3] + t[:, None, None] * rays[None]  # (steps, rays, 3)
        below = pts[..., 2] <= self.terrain.height_at(pts[..., 0], pts[..., 1])
        hit = below.any(axis=0)
        return pts[below.argmax(axis=0)[hit], np.flatnonzero(hit), :2]

    def textured_view_fraction(self, camera: str) -> float:
        """Truth, for the evaluator: the fraction of :meth:`ground_view_xy_m` on textured ground. Without
        ``appearance.fine_soil`` all ground is ordinary, textured soil (1.0); with it, only the scenario's
        ``texture_patches`` discs are (the scenario says where texture exists). 0.0 when no ray meets ground."""
        ap = self.scenario.appearance
        if not ap.fine_soil:
            return 1.0
        xy = self.ground_view_xy_m(camera)
        if not len(xy):
            return 0.0
        on = np.zeros(len(xy), dtype=bool)
        for p in ap.texture_patches:
            on |= np.hypot(xy[:, 0] - p.x_m, xy[:, 1] - p.y_m) <= p.radius_m
        return float(on.mean())

    def start_pose(self) -> Pose:
        """The operator-given start pose of the drive (from the previous localisation and sun finding)."""
        return self.operator_start_pose

    def close(self) -> None:
        self.sensors.detach()
        self.renderer.close()
