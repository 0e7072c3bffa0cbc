"""The onboard stack: what flight software computed from sensor data alone (kiss-icp ``register_frame`` style).

Every entry point takes an :class:`~rover_sim.world.observation.Observation` and refuses anything else, so the
honesty rule is a type, not a convention. Nothing here imports the simulator, the renderer or the evaluator.

- :meth:`Onboard.observe`: each encoder reading with the IMU samples up to it -> two dead reckoners (one pure
  wheel/IMU for comparison, one that VO corrects: the pose the rover drives on), at the encoders' 8 Hz.
- :meth:`Onboard.rectified`: a raw pair (flight profile) -> the rectified pair, through the calibrated camera
  models carried by the observation (MER rectified before stereo and VO); every use of a pair goes through it.
- :meth:`Onboard.vo_step`: one stereo pair -> VO (seed 000 section 2) -> an accepted motion replaces the
  dead-reckoned increment since the previous pair (MER practice); a refusal leaves dead reckoning standing.
  ``vo_update = "position"`` (MER's default, Ali et al. 2005) replaces the position only and keeps the IMU's
  attitude; ``"full_pose"`` takes VO's attitude too.
- :meth:`Onboard.plan`: hazcam pair(s) -> stereo range image -> points placed with the onboard pose -> GESTALT
  (seed 001 section 4) -> the arc to drive.
"""

from __future__ import annotations

import bisect
import inspect
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from nav.camera import StereoRig, transform_points
from nav.dead_reckoning import DeadReckoner
from nav.epipolar import EpipolarCheck
from nav.geometry import se3_inv
from nav.protocols import Planner, StereoMatcher, VisualOdometer
from nav.rectify import Rectification, StereoCalibration, rectification
from nav.stereo import RangeImage, range_image_with
from nav.trajectory import Pose
from nav.types import ImuSample, RoverGeometry
from nav.vo.params import VoParams
from nav.vo.shadow import RoverShape, predict_shadow, vo_feature_mask
from nav.vo.texture import points_in_view, trackable_points, view_overlap
from rover_sim.world.observation import Observation, StereoImages, require_observation

# Hazcam look-ahead on MER: 3-4 m useful. At 256^2 (10 cm baseline) the disparity at 3.5 m is ~2 px and
# elevation errors there reach 10-20 cm, as big as the steps GESTALT must see; farther points only add false rocks.
MAX_RANGE_M = 3.5
# The rover's own wheels are in the hazcams' view (front wheels, more so when steered): points inside the rover's
# plan-view box (rover frame, |x| and |y| below these) are the vehicle, not terrain.
SELF_MASK_HALF_LENGTH_M = 0.85
SELF_MASK_HALF_WIDTH_M = 0.8
IMU_TIME_TOL_S = 1e-9  # an IMU sample taken with an encoder reading (same instant) belongs to its update


def terrain_points(points_rover: np.ndarray) -> np.ndarray:
    """Range points worth mapping: within ``MAX_RANGE_M`` and outside the rover's own plan-view box."""
    xy = points_rover[:, :2]
    own = (np.abs(xy[:, 0]) < SELF_MASK_HALF_LENGTH_M) & (np.abs(xy[:, 1]) < SELF_MASK_HALF_WIDTH_M)
    return points_rover[(np.hypot(xy[:, 0], xy[:, 1]) < MAX_RANGE_M) & ~own]


def accepts_feature_mask(vo: object) -> bool:
    """Whether ``vo.step`` takes a ``feature_mask`` keyword (the built-in does; a plugin may)."""
    if hasattr(vo, "takes_mask"):  # a guarded plugin says whether the wrapped step() declares it
        return bool(vo.takes_mask)
    try:
        params = inspect.signature(vo.step).parameters  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        return False
    return "feature_mask" in params or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())


def heading_rad(R_world_rover: np.ndarray) -> float:
    return float(math.atan2(R_world_rover[1, 0], R_world_rover[0, 0]))


@dataclass(frozen=True)
class VoStep:
    """One VO step as the rover saw it: the result, the wheel odometry's distance since the previous pair, the
    slip VO measured (NaN unless accepted), and the step's compute time."""

    result: object  # nav.vo.VoResult (or a plugin's result honouring nav.protocols.VisualOdometer)
    commanded_m: float
    vo_slip: float
    ms: float
    predicted_motion_rover: np.ndarray  # the dead-reckoned motion VO was seeded with
    R_world_rover_prev: np.ndarray  # onboard attitude at the previous pair
    feature_mask: np.ndarray | None = None  # False where features were barred (predicted shadow, rover hardware)


@dataclass(frozen=True)
class PlanCycle:
    """One autonav cycle: the planner's decision and what it was made from (for the recording)."""

    decision: object  # nav.gestalt.Decision
    range_image: RangeImage
    points_world: np.ndarray
    T_world_rover: np.ndarray  # the onboard pose the points were placed with
    ms: float


class Onboard:
    """Dead reckoning, visual odometry and local planning on sensor data only."""

    def __init__(
        self,
        start_pose: Pose,
        vo: VisualOdometer | None,
        stereo: StereoMatcher,
        planner_factory: Callable[[], Planner],
        geometry: RoverGeometry | None = None,
        shape: RoverShape | None = None,
        vo_update: str = "position",
        epipolar_check: bool = True,
        on_event: Callable[[str], None] | None = None,
        stereo_rotation_sigma_rad: float | None = None,
    ) -> None:
        if vo_update not in ("position", "full_pose"):
            raise ValueError(f"[nav.vo] update = {vo_update!r}: allowed values are 'position' and 'full_pose'")
        self.vo_update = vo_update
        self.geometry = geometry or RoverGeometry()
        self.shape = shape  # design data for the shadow prediction (None: no shadow masking)
        self.dead_reckoning = DeadReckoner(self.geometry, start_pose)  # wheels + IMU only, for comparison
        self.estimator = DeadReckoner(self.geometry, start_pose, odometry=self.dead_reckoning.odometry)  # VO-corrected
        self.vo = vo
        self.stereo = stereo
        self.planner_factory = planner_factory
        self.planner: Planner | None = None
        self._imu_pending: list[ImuSample] = []
        self._last_frame_distance_m = 0.0
        self._vo_takes_mask = vo is not None and accepts_feature_mask(vo)
        self._last_pair: tuple | None = None  # (left, right, rig, mask) of the previous VO pair
        self._rectified: dict[str, tuple[np.ndarray, StereoImages]] = {}  # camera -> (raw left, rectified pair)
        # per stereo pair: the in-flight epipolar check (nav.epipolar), None when off
        self.epipolar: dict[str, EpipolarCheck] | None = {} if epipolar_check else None
        self._stereo_rotation_sigma_rad = stereo_rotation_sigma_rad  # the calibration's stated 1 sigma (per axis)
        self._on_event = on_event

    @property
    def pose(self) -> Pose:
        return self.estimator.pose

    # ------------------------------------------------------------------ dead reckoning
    def observe(self, obs: Observation) -> Pose:
        """Fold in the IMU and encoder samples of ``obs``; returns the onboard pose."""
        obs = require_observation(obs, "Onboard.observe")
        self._imu_pending.extend(obs.imu)
        for enc in obs.encoders:  # 8 Hz pose updates: each reading with the IMU samples taken up to it
            n = bisect.bisect_right([s.t_s for s in self._imu_pending], enc.t_s + IMU_TIME_TOL_S)
            upto, self._imu_pending = self._imu_pending[:n], self._imu_pending[n:]
            self.dead_reckoning.update(upto, enc)
            self.estimator.update(upto, enc)
        return self.estimator.pose

    # ------------------------------------------------------------------ rectification
    def rectified(self, obs: Observation, camera: str, refine: EpipolarCheck | None = None) -> StereoImages:
        """``camera``'s pair of ``obs``, rectified with its calibrated models (unchanged if already rectified).

        Stereo and VO then triangulate with the rectified pinhole rig, which is triangulating through the models:
        each rectified pixel carries the ray its raw pixel has under the calibrated CAHVOR/fisheye model
        (:mod:`nav.rectify`), so calibration errors reach the estimates as they did on MER. With the epipolar
        check on (``[nav] epipolar_check``), the pair's first images also fit the right camera's relative pitch
        and roll from their row disparities (:mod:`nav.epipolar`; the toe-in, which biases range, is not
        observable this way and stays); from the pair that completes the fit on, every pair is rectified with the
        corrected calibration. The tables are cached per calibration and the last rectified pair per camera is
        reused.

        ``refine``: a second check applied on top of the camera's own, with its own state (the rock survey's
        full-resolution panoramas fit the relative focal length there, :class:`nav.epipolar.EpipolarCheck`
        ``fit_scale``); such pairs bypass the per-camera cache."""
        pair = require_observation(obs, "Onboard.rectified").pair(camera)
        if pair.calibration is None:
            return pair
        hit = self._rectified.get(camera)
        if refine is None and hit is not None and hit[0] is pair.left_u8:
            return hit[1]
        calib, rect = pair.calibration, None
        for check in self._checks(camera, refine):
            calib, rect = self._checked(camera, check, calib, pair, rect)
        rect = rect if rect is not None else rectification(calib)
        out = StereoImages(camera, pair.t_s, *rect.apply(pair.left_u8, pair.right_u8), rect.rig)
        if refine is None:
            self._rectified[camera] = (pair.left_u8, out)
        return out

    def rectifying_calibration(self, obs: Observation, camera: str) -> StereoCalibration | None:
        """The calibrated models :meth:`rectified` rectifies ``camera``'s pair of ``obs`` with, as things stand:
        the pair's own, corrected by the camera's epipolar check once its fit is in (after :meth:`rectified` of
        the pair: exactly what it used); None for a pair that arrives rectified. Observes nothing."""
        pair = require_observation(obs, "Onboard.rectifying_calibration").pair(camera)
        if pair.calibration is None:
            return None
        check = None if self.epipolar is None else self.epipolar.get(camera)
        return pair.calibration if check is None else check.calibration(pair.calibration)

    def _checks(self, camera: str, refine: EpipolarCheck | None) -> list[EpipolarCheck]:
        """The epipolar checks ``camera``'s pairs go through, in order (the camera's own, then ``refine``)."""
        checks = []
        if self.epipolar is not None:
            checks.append(
                self.epipolar.setdefault(camera, EpipolarCheck(prior_sigma_rad=self._stereo_rotation_sigma_rad))
            )
        if refine is not None:
            checks.append(refine)
        return checks

    def _checked(
        self,
        camera: str,
        check: EpipolarCheck,
        calib: StereoCalibration,
        pair: StereoImages,
        rect: Rectification | None,
    ) -> tuple[StereoCalibration, Rectification | None]:
        """``calib`` as ``check`` corrects it, and ``calib``'s rectification ``rect`` (None: not built yet) if the
        check left ``calib`` as it was. A check without a fit yet that can resolve this pair is shown it rectified
        with ``calib`` (and may complete its fit with it)."""
        if check.correction is None:
            rect = rect if rect is not None else rectification(calib)
            if check.resolvable(rect.rig) and check.observe(calib, rect.rig, *rect.apply(pair.left_u8, pair.right_u8)):
                self._report_fit(camera, check)
        corrected = check.calibration(calib)
        return corrected, (rect if corrected is calib else None)

    def _report_fit(self, camera: str, check: EpipolarCheck) -> None:
        """The events-log line of a check's completed fit."""
        fit = check.fit
        if self._on_event is None or fit is None:
            return
        scale = f", focal length {1e2 * fit.scale:+.3f} %" if check.fit_scale else ""
        self._on_event(
            f"epipolar check ({camera}): right camera pitch {1e3 * fit.rotation_rad[0]:+.3f} mrad, roll "
            f"{1e3 * fit.rotation_rad[2]:+.3f} mrad{scale} from {fit.n_matches} corners; row disparity "
            f"{fit.before_px:.3f} -> {fit.after_px:.3f} px (median)"
        )

    # ------------------------------------------------------------------ visual odometry
    def vo_step(self, obs: Observation, camera: str) -> VoStep:
        """Run VO on ``obs``'s ``camera`` pair and apply an accepted motion to the onboard pose."""
        obs = require_observation(obs, "Onboard.vo_step")
        if self.vo is None:
            raise RuntimeError("VO is off in this configuration ([nav.vo] enabled = false)")
        pair = self.rectified(obs, camera)
        est = self.estimator
        pred = est.predicted_motion_rover()
        commanded = est.distance_m - self._last_frame_distance_m
        prev_R = est.vo_frame_pose.R_world_rover
        t0 = time.perf_counter()
        mask = self.feature_mask(obs, camera) if self._vo_takes_mask else None
        if mask is None:
            res = self.vo.step(pair.left_u8, pair.right_u8, pair.rig, pred, R_world_rover=prev_R)
        else:
            res = self.vo.step(pair.left_u8, pair.right_u8, pair.rig, pred, R_world_rover=prev_R, feature_mask=mask)
        ms = (time.perf_counter() - t0) * 1e3
        ok = res.status == "ok"
        slip = 1.0 - float(res.motion_rover[0, 3]) / commanded if ok and abs(commanded) > 1e-3 else math.nan
        if ok:
            est.apply_vo_correction(res.motion_rover, update_attitude=self.vo_update == "full_pose")
        else:
            est.mark_vo_frame()
        self._last_frame_distance_m = est.distance_m
        self._last_pair = (pair.left_u8, pair.right_u8, pair.rig, mask)
        return VoStep(res, commanded, slip, ms, pred, prev_R, mask)

    # ------------------------------------------------------------------ texture-seeking pointing
    @property
    def texture_params(self) -> VoParams:
        return getattr(self.vo, "params", None) or VoParams()

    @property
    def ground_z_m(self) -> float:
        return self.shape.ground_z_m if self.shape is not None else -self.geometry.body_height_m

    def planned_view_texture(self, rig: StereoRig) -> int | None:
        """Trackable features of the previous VO pair that the planned view ``rig`` will see after the
        dead-reckoned motion (None before the first pair)."""
        if self._last_pair is None:
            return None
        left, right, prev_rig, mask = self._last_pair
        pts = trackable_points(left, right, prev_rig, self.texture_params, mask)
        return points_in_view(pts, rig.left, se3_inv(self.estimator.predicted_motion_rover()))

    def candidate_texture(self, obs: Observation, camera: str) -> tuple[int, float]:
        """For a candidate pointing's pair: (its trackable features inside the previous pair's view, the
        predicted ground overlap with the previous pair)."""
        obs = require_observation(obs, "Onboard.candidate_texture")
        pair = self.rectified(obs, camera)
        if self._last_pair is None:
            return 0, 0.0
        prev_rig, motion = self._last_pair[2], self.estimator.predicted_motion_rover()
        overlap = view_overlap(prev_rig.left, pair.rig.left, motion, self.ground_z_m)
        mask = self.feature_mask(obs, camera)
        pts = trackable_points(pair.left_u8, pair.right_u8, pair.rig, self.texture_params, mask)
        return points_in_view(pts, prev_rig.left, motion), overlap

    def feature_mask(self, obs: Observation, camera: str) -> np.ndarray | None:
        """False where the rover's own shadow (or the rover) is predicted in ``camera``'s left image: from the
        ephemeris sun direction, the design shape, the calibrated camera model and the onboard attitude."""
        obs = require_observation(obs, "Onboard.feature_mask")
        if self.shape is None or obs.sun_direction_world is None:
            return None
        rig = obs.pair(camera).rig
        T_navcam = rig.left.T_rover_cam if camera == "navcam" else None
        pred = predict_shadow(
            self.shape, rig.left, self.estimator.pose.R_world_rover, obs.sun_direction_world, T_navcam
        )
        return vo_feature_mask(pred)

    def reset_vo(self) -> None:
        """Forget the previous pair (the cameras were repointed)."""
        self._last_pair = None
        if self.vo is not None:
            self.vo.reset()

    # ------------------------------------------------------------------ stereo and planning
    def range_image(self, obs: Observation, camera: str) -> RangeImage:
        pair = self.rectified(require_observation(obs, "Onboard.range_image"), camera)
        return range_image_with(self.stereo, pair.left_u8, pair.right_u8, pair.rig)

    def start_planning(self) -> None:
        """A fresh planner (empty goodness map) for a new autonav command."""
        self.planner = self.planner_factory()

    def plan(self, obs: Observation, goal_xy: np.ndarray, cameras: Sequence[str]) -> PlanCycle:
        """One GESTALT cycle on the pairs of ``cameras`` (the first is the forward-looking one)."""
        obs = require_observation(obs, "Onboard.plan")
        if self.planner is None:
            self.start_planning()
        pose = self.estimator.pose
        t0 = time.perf_counter()
        ri = self.range_image(obs, cameras[0])
        pts = terrain_points(ri.points_rover_m())
        for cam in cameras[1:]:
            pts = np.vstack([pts, terrain_points(self.range_image(obs, cam).points_rover_m())])
        T = pose.as_matrix()
        pts_world = transform_points(T, pts)
        yaw = heading_rad(T[:3, :3])
        decision = self.planner.step(pts_world, np.array([T[0, 3], T[1, 3], yaw]), goal_xy)  # type: ignore[union-attr]
        return PlanCycle(decision, ri, pts_world, T, (time.perf_counter() - t0) * 1e3)

    def keep_out_violation(self, zones: Sequence[tuple[str, float, float, float]]) -> tuple[str, float] | None:
        """The first zone (name, x, y, radius) the onboard pose is inside, with its distance; None if clear."""
        p = self.estimator.pose.position_xyz_m
        for name, x, y, r in zones:
            d = math.hypot(p[0] - x, p[1] - y)
            if d < r:
                return name, d
        return None
