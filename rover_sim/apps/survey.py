"""Rock-based cross-site localisation in the simulator: drive to sites, navcam stereo panoramas, evaluation.

The pipeline object (:class:`RockSiteSurvey`) owns a :class:`~rover_sim.runtime.runner.Mission` (terrain, physics,
sensors, dead reckoning, VO) and a high-resolution navcam renderer; the algorithms in :mod:`nav.rocks` know none of
them.
A scenario's sites are its start pose plus the end of every ``goto`` command (``scenarios/rock_localization.toml``):
the rover drives to each with the runner's VO-corrected goto, stops, stands for ``REST_BEFORE_PANORAMA_S`` (the dead
reckoner re-levels roll and pitch from the accelerometers at rest, so the site frame is level: the paper's site frames
differ by heading and translation only) and takes a panorama:

1. the mast sweeps the navcam pair in pan (``pan_step_deg``) at each ``elevations_deg``; every pair is rendered at
   ``resolution_px`` through the scenario's sensor profile, as the mission's own pairs are (:meth:`panorama_pair`),
   and matched by :func:`nav.rocks.panorama_points` (binned near field, full-resolution far field). In the flight
   profile the survey's first pair also runs a full-resolution epipolar check on top of the navcam's own
   (``SurveyConfig.focal_check``): the right camera's relative pitch, roll and focal length from its rows
   (:class:`nav.epipolar.EpipolarCheck` ``fit_scale``), applied to every panorama pair after it;
2. rover-frame points are mapped into the world through the **onboard pose estimate** (VO-corrected dead
   reckoning; never the truth), the rover's own body is cut out, the cloud is cropped to ``max_range_m`` and thinned
   to ``voxel_m``;
3. :func:`nav.rocks.extract_rocks` extracts and models the rocks.

On the ground (:func:`calibrate_range_bias`, before the final adjustment) the panorama pair's stereo range bias is
fitted from the rocks matched between sites and the rocks moved back along their lines of sight
(:mod:`nav.rocks.range_bias`: a toe-in calibration error adds a constant to inverse range). The chain of sites is
then adjusted by :class:`nav.rocks.SiteChain`: matches between every two sites within 26 m (estimated) give
site-to-site transforms, fused with the odometry legs, each weighted by its own covariance; a leg's is the sum of
the covariances VO reports for its steps (the survey wraps the mission's VO step to collect them), plus on a
calibrated rig VO's systematic part (``VO_SYSTEMATIC_SIGMA_FRAC`` of the leg: the calibration biases every step
alike), plus the gyro's heading drift over the leg's duration. Ground truth (the terrain's rock list, the
simulator's rover pose) is used only by the ``evaluate_*`` functions of :mod:`rover_sim.apps.survey_eval`: to map a
site's estimated frame onto the true world (truth pose composed with the inverse onboard pose) and to associate
extracted rocks with the generated ones.

Sensor profile: with ``[sensors.lens]`` on (flight) the panorama pairs are raw images through the run's true lenses
(:mod:`rover_sim.render.lens`) and the CCD image formation (:mod:`rover_sim.render.imaging`), rectified on board
with the run's *calibrated* models at the *commanded* mast pointing (the mast stops within its encoder errors):
:func:`rover_sim.world.calibration.onboard_stereo_models` and
:meth:`rover_sim.runtime.onboard.Onboard.rectified`, the calls the mission's own pairs go through, with the same
seeded calibration draw. The ``ideal`` profile renders the exact pinhole pairs, as before. At 2048 px a
rendered pixel is a quarter of a 1024^2 CCD photosite; the image formation then gives each pixel a photosite's
noise (it never splits a photosite), a little noisier than an upsampled 1024^2 image.

Dead reckoning and VO estimates come from the same drive: the runner keeps a pure wheel/IMU dead reckoner beside
the onboard (VO-corrected) one, so both are measured, not simulated.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np

from nav.epipolar import EpipolarCheck
from nav.geometry import quat_wxyz_to_R
from nav.rocks import (
    ChainParams,
    ExtractedRock,
    PanoramaStereoParams,
    RockParams,
    SiteChain,
    SiteRocks,
    extract_rocks,
    panorama_points,
    voxel_downsample,
)
from nav.rocks.range_bias import RangeBiasFit, correct_rocks, corrected_points, estimate_inverse_range_bias
from rover_sim.runtime.onboard import VoStep
from rover_sim.runtime.runner import Mission
from rover_sim.scenario.commands import GotoCmd
from rover_sim.scenario.schema import Scenario
from rover_sim.sim.drive import TICK_S
from rover_sim.world.calibration import build_true_lens, onboard_stereo_models
from rover_sim.world.observation import Observation, StereoImages
from terrains import Terrain

ROVER_BOX_HALF_M = (1.2, 1.45)  # rover-frame |x|, |y| of the rover's own body, wings and wheels: points cut out
MAST_SETTLE_S = 1.5  # mast servo settling after a pan step (it tracks to ~1e-5 rad in 2 s)
REST_BEFORE_PANORAMA_S = 3.0  # the rover stands this long after a drive: the suspension settles and the dead
# reckoner re-levels roll and pitch from the accelerometers (at rest) before the panorama is mapped through its pose
VO_FAILED_STEP_SIGMA_FRAC = 0.1  # a step VO did not correct is the wheel odometry's: this fraction of its length
# VO's systematic error on a calibrated (flight) rig, per axis, as a fraction of the leg: the step covariance VO
# reports is its fit's (feature noise), but the calibration's errors (toe-in, range scale) bias every step of a leg
# the same way, so they add up with the distance, not with its square root. 1 % is MER VO's accuracy figure
# (REFERENCE section 3.4: MSSTB under 1 %), not fitted here. Without it the summed step covariances were 20-40 times
# too small in sigma: 1-2 mm against 3-7 cm errors on the survey's 13-16 m legs (chi-square 350-3400, 3 dof;
# docs/navigation/rock-localization.md)
VO_SYSTEMATIC_SIGMA_FRAC = 0.01


@dataclass(frozen=True)
class SurveyConfig:
    """How a site's panorama is taken and processed."""

    resolution_px: int = 2048  # navcam images of the panorama (flight navcams: 1024; see PanoramaStereoParams)
    pan_step_deg: float = 40.0  # 45 deg field of view: 5 deg overlap
    elevations_deg: tuple[float, ...] = (-10.0,)  # -10 deg: the frame spans 2.2 m from the mast to the horizon
    max_range_m: float = 32.0  # points farther than this (horizontally) from the cameras are dropped
    voxel_m: float = 0.02  # thinning of the dense near field
    shadows: bool = True
    shadow_half_extent_m: float = 30.0  # rocks cast shadows across the whole panorama
    image_noise: bool = True
    # flight profile: the true-lens render of the panoramas at twice the raw pixels' magnification, each raw pixel
    # integrating its area (rover_sim.render.lens.TrueLens). At 1x the raw image is a bilinear read of a render
    # at its own scale, then rectified (bilinear again): at 2048 px the far field lost a third of its stereo points
    # (1.0 M per frame against 1.5 M ideal; 1.2 M at 2x). Navigation images keep the scenario's
    # sensors.lens.render_oversample (1): changing it re-records every flight baseline
    render_oversample: float = 2.0
    # flight profile: the panoramas' own epipolar check, with the relative focal length (see the module docstring).
    # A 0.07 % relative focal error (1 sigma of the flight calibration) is 0.7 px of disparity at the edges of a
    # 2048 px frame, 3 % of range at 20 m: seed 3's draw (0.11 %) tripled the ground's height spread at every range
    # and gave the survey 394 phantom rocks; its rows alone fit +0.113 % there (docs/navigation/index.md)
    focal_check: bool = True
    stereo: PanoramaStereoParams = PanoramaStereoParams()
    rocks: RockParams = RockParams()


@dataclass
class SiteSurvey:
    """One site: the poses (truth kept for evaluation only), the ground points and the extracted rocks."""

    index: int
    t_s: float
    T_world_rover_true: np.ndarray  # (4, 4) evaluation only
    T_world_rover_dr: np.ndarray  # (4, 4) wheel/IMU dead reckoning
    T_world_rover_onboard: np.ndarray  # (4, 4) VO-corrected: the frame the points and rocks are in
    driven_m: float  # odometry distance since the previous site
    sensor_xyz_m: np.ndarray  # navcam position (mean of the left cameras) in the onboard frame
    rocks: list[ExtractedRock]
    n_points: int
    timings_s: dict[str, float] = field(default_factory=dict)
    points: np.ndarray | None = None  # (N, 3) onboard frame, kept only with keep_points
    leg_s: float = 0.0  # time since the previous site (the gyro's heading drift grows with it)
    odometry_cov_m2: np.ndarray | None = None  # (3, 3) world covariance VO itself reports for the leg (its steps)

    def site_rocks(self) -> SiteRocks:
        return SiteRocks(self.rocks, self.sensor_xyz_m)

    def estimated_to_true(self) -> np.ndarray:
        """4x4 map of this site's onboard (estimated) world frame onto the true world (evaluation only)."""
        return self.T_world_rover_true @ np.linalg.inv(self.T_world_rover_onboard)


class RockSiteSurvey:
    """Drive a scenario's sites and take a stereo panorama at each (see the module docstring).

    ``progress(message)`` is called at every site and pan step. Close it (or use it as a context manager) to free
    the renderers' GL contexts.
    """

    def __init__(
        self,
        scenario: Scenario,
        config: SurveyConfig = SurveyConfig(),
        progress: Callable[[str], None] | None = None,
        keep_points: bool = False,
    ) -> None:
        from rover_sim.render.config import ImageNoise, RenderConfig
        from rover_sim.render.renderer import StereoRenderer

        self.sc = scenario
        self.config = config
        self.progress = progress or (lambda _msg: None)
        self.keep_points = keep_points
        t0 = time.perf_counter()
        self.mission = Mission(scenario)
        self.calibration = self.mission.world.calibration  # the run's true lenses and calibration (None: ideal)
        noise = ImageNoise(seed=scenario.seed + 1) if config.image_noise else None
        sim = self.mission.sim
        lens = None
        if self.calibration is not None:  # the run's navcams at the panorama's resolution
            lens = build_true_lens(sim.model, sim.data, self.calibration, config.resolution_px, pairs=("navcam",),
                                   render_oversample=config.render_oversample)  # fmt: skip
        self.renderer = StereoRenderer(
            sim,
            RenderConfig(
                resolution_px=config.resolution_px,
                noise=noise,
                shadows=config.shadows and scenario.sun.shadows,
                shadow_half_extent_m=config.shadow_half_extent_m,
                imaging=scenario.sensors.imaging,  # "ideal": ``noise`` as before; "ccd": the flight image chain
                imaging_seed=scenario.seed + 1,
            ),
            lens=lens,
        )
        # the panoramas' full-resolution epipolar check, with the relative focal length (None: ideal or off)
        self.focal_check = EpipolarCheck(fit_scale=True) if config.focal_check and self.calibration else None
        self.build_s = time.perf_counter() - t0
        self.sites: list[SiteSurvey] = []
        self._last_distance_m = 0.0
        self._last_t_s = 0.0
        self._leg_cov = np.zeros((3, 3))
        self.mission.vo_listeners.append(self._add_leg_covariance)

    def _add_leg_covariance(self, step: VoStep, _T_rover_cam: np.ndarray) -> None:
        """Sum, over the leg, the position covariance VO reports for every step it accepts (rotated into the world
        by the attitude at the previous pair), and the wheel odometry's for a step it refuses. The chain adjustment
        weighs the leg by it (VO's own error model, not the truth)."""
        res = step.result
        R = np.asarray(step.R_world_rover_prev, dtype=float)
        if res.status == "ok" and res.covariance is not None:
            self._leg_cov += R @ np.asarray(res.covariance)[:3, :3] @ R.T
        elif res.status != "first_frame":
            d = float(np.linalg.norm(np.asarray(step.predicted_motion_rover)[:3, 3]))
            self._leg_cov += (VO_FAILED_STEP_SIGMA_FRAC * d) ** 2 * np.eye(3)

    def _vo_systematic_cov_m2(self, driven_m: float) -> np.ndarray:
        """VO's systematic error over a leg of ``driven_m`` (``VO_SYSTEMATIC_SIGMA_FRAC`` per axis) on a calibrated
        rig; none on the ideal profile's exact cameras (whose VO errors are its fit's)."""
        frac = VO_SYSTEMATIC_SIGMA_FRAC if self.calibration is not None else 0.0
        return (frac * driven_m) ** 2 * np.eye(3)

    @property
    def terrain(self) -> Terrain:
        return self.mission.terrain

    def close(self) -> None:
        self.renderer.close()
        self.mission.close()

    def __enter__(self) -> RockSiteSurvey:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ the mission
    def run(self, max_sites: int | None = None) -> list[SiteSurvey]:
        """Survey the start site, then drive each ``goto`` and survey its end; returns the sites."""
        m = self.mission
        m.tick()
        if m.onboard.vo is not None:
            m.vo_update()  # the first pair initialises VO
        self.survey_site()
        for cmd in self.sc.commands:
            if max_sites is not None and len(self.sites) >= max_sites:
                break
            t0 = time.perf_counter()
            m.run_command(cmd)
            if isinstance(cmd, GotoCmd):
                self.progress(f"drove to site {len(self.sites)} in {time.perf_counter() - t0:.0f} s")
                self.survey_site(drive_s=time.perf_counter() - t0)
        return self.sites

    def survey_site(self, drive_s: float = 0.0) -> SiteSurvey:
        """Panorama at the current stop: points through the onboard pose, then rock extraction."""
        m, cfg = self.mission, self.config
        timings = {"drive": drive_s, "render": 0.0, "stereo": 0.0}  # render: acquisition and rectification
        sim = m.sim
        self._stand(REST_BEFORE_PANORAMA_S)
        T_onboard = m.onboard.pose.as_matrix()  # the panorama is mapped through this estimate
        T_dr = m.onboard.dead_reckoning.pose.as_matrix()
        T_true = np.eye(4)  # evaluation only
        T_true[:3, :3] = quat_wxyz_to_R(sim.quat_wxyz())
        T_true[:3, 3] = sim.position_m()
        clouds, sensors = [], []
        for elevation in cfg.elevations_deg:
            for pan in self._pans():
                self._point_mast(pan, elevation)
                t0 = time.perf_counter()
                pair = self.panorama_pair()
                rig = pair.rig
                t1 = time.perf_counter()
                pts = panorama_points(pair.left_u8, pair.right_u8, rig, cfg.stereo)
                timings["render"] += t1 - t0
                timings["stereo"] += time.perf_counter() - t1
                body = (np.abs(pts[:, 0]) < ROVER_BOX_HALF_M[0]) & (np.abs(pts[:, 1]) < ROVER_BOX_HALF_M[1])
                pts = pts[~body]
                clouds.append(voxel_downsample(pts @ T_onboard[:3, :3].T + T_onboard[:3, 3], cfg.voxel_m))
                sensors.append(T_onboard[:3, :3] @ rig.left.T_rover_cam[:3, 3] + T_onboard[:3, 3])
                self.progress(f"site {len(self.sites)}: pan {pan:+.0f} deg, {len(pts)} points")
        self._point_mast(self.sc.nav.mast_pan_deg, self.sc.nav.mast_tilt_deg)  # back to the navigation pointing
        sensor = np.mean(sensors, axis=0)
        t0 = time.perf_counter()
        cloud = np.concatenate(clouds)
        horiz = np.hypot(cloud[:, 0] - sensor[0], cloud[:, 1] - sensor[1])
        cloud = voxel_downsample(cloud[horiz <= cfg.max_range_m], cfg.voxel_m)
        rocks = extract_rocks(cloud, cfg.rocks, sensor_xyz=sensor)
        timings["extract"] = time.perf_counter() - t0
        driven_m = m.onboard.estimator.distance_m - self._last_distance_m
        site = SiteSurvey(
            index=len(self.sites),
            t_s=sim.time_s,
            T_world_rover_true=T_true,
            T_world_rover_dr=T_dr,
            T_world_rover_onboard=T_onboard,
            driven_m=driven_m,
            leg_s=sim.time_s - self._last_t_s,
            odometry_cov_m2=self._leg_cov + self._vo_systematic_cov_m2(driven_m),
            sensor_xyz_m=sensor,
            rocks=rocks,
            n_points=len(cloud),
            timings_s=timings,
            points=cloud if self.keep_points else None,
        )
        self._last_distance_m = m.onboard.estimator.distance_m
        self._last_t_s = sim.time_s
        self._leg_cov = np.zeros((3, 3))
        self.sites.append(site)
        self.progress(f"site {site.index}: {len(rocks)} rocks from {len(cloud)} points")
        return site

    def panorama_pair(self) -> StereoImages:
        """The navcam pair at the current (settled) pointing, as stereo sees it: ideal profile, the pinhole pair and
        its exact rig; otherwise the pair the sensor profile delivers with the onboard models at the commanded
        pointing, through the onboard rectification (see the module docstring)."""
        world = self.mission.world
        if self.calibration is None and not self.sc.sensors.lens.has_mast_error:
            rig = self.renderer.rig("navcam")
            frame = self.renderer.render_pair("navcam")
            return StereoImages("navcam", frame.t_s, frame.left, frame.right, rig)
        sim, px = world.sim, self.config.resolution_px
        pan, elevation = world.mast_pan_deg, world.mast_elevation_deg  # commanded
        rig, calib = onboard_stereo_models(sim.model, sim.data, self.calibration, "navcam", px, pan, elevation)
        frame = self.renderer.render_pair("navcam")
        images = {"navcam": StereoImages("navcam", frame.t_s, frame.left, frame.right, rig, calib)}
        obs = Observation(t_s=frame.t_s, images=MappingProxyType(images), mast_pan_deg=world.mast_pan_deg,
                          mast_elevation_deg=world.mast_elevation_deg)  # fmt: skip
        return self.mission.onboard.rectified(obs, "navcam", refine=self.focal_check)

    def _pans(self) -> list[float]:
        n = max(1, int(round(360.0 / self.config.pan_step_deg)))
        step = 360.0 / n
        return [-180.0 + step * (k + 0.5) for k in range(n)]

    def _stand(self, duration_s: float) -> None:
        """Let the rover stand still (wheels idle) for ``duration_s``; the onboard estimators keep running."""
        self.mission.stand(duration_s, TICK_S)

    def _point_mast(self, pan_deg: float, elevation_deg: float) -> None:
        """Point the navcams (pan left positive, elevation up positive) and let the mast settle."""
        self.mission.world.point_mast(pan_deg, elevation_deg)
        self.mission.stand(MAST_SETTLE_S, TICK_S)


# ================================================================================================================
# Chain of sites
# ================================================================================================================


def adjust_chain(sites: list[SiteSurvey], params: ChainParams = ChainParams()) -> SiteChain:
    """Feed the sites, in order, to an incremental :class:`nav.rocks.SiteChain`: onboard poses, the legs' durations
    and VO's own covariances only (no truth)."""
    chain = SiteChain(params)
    for s in sites:
        T = s.T_world_rover_onboard
        yaw = math.atan2(T[1, 0], T[0, 0])
        chain.add_site(s.site_rocks(), T[:3, 3], s.driven_m, yaw, s.leg_s, s.odometry_cov_m2)
    return chain


RANGE_BIAS_SIGNIFICANCE_CHI2 = 10.83  # chi-square, 1 dof, 99.9 %: the fitted bias must lower the summed cost this much


@dataclass(frozen=True)
class RangeCalibration:
    """Ground processing's self-calibration of the panorama stereo range bias (:mod:`nav.rocks.range_bias`)."""

    fit: RangeBiasFit | None  # None: no site pair with enough matched rocks
    applied: bool  # the fit lowered the cost significantly and the rocks were corrected

    @property
    def beta_per_m(self) -> float:
        return self.fit.beta_per_m if self.applied and self.fit is not None else 0.0


def calibrate_range_bias(
    sites: list[SiteSurvey], params: ChainParams = ChainParams()
) -> tuple[list[SiteSurvey], RangeCalibration]:
    """Fit the panorama pair's inverse-range bias on the rocks the chain matches between sites and, if it is
    significant (a likelihood-ratio drop of ``RANGE_BIAS_SIGNIFICANCE_CHI2``), move every site's rocks (and kept
    points) along their lines of sight (:func:`nav.rocks.range_bias.correct_rocks`). The flight profile's stereo
    calibration leaves a toe-in that no single pair shows; MER's rock localisation ran on the ground, where this
    belongs. Uses the onboard frames only (no truth)."""
    chain = adjust_chain(sites, params)
    fit = estimate_inverse_range_bias([s.site_rocks() for s in sites], chain.matches, params.match)
    if fit is None or fit.cost_at_zero - fit.cost_at_fit < RANGE_BIAS_SIGNIFICANCE_CHI2:
        return sites, RangeCalibration(fit, False)
    out = []
    for s in sites:
        rocks = correct_rocks(s.site_rocks(), fit.beta_per_m).rocks
        points = None if s.points is None else corrected_points(s.points, s.sensor_xyz_m, fit.beta_per_m)
        out.append(replace(s, rocks=rocks, points=points))
    return out, RangeCalibration(fit, True)
