"""The swappable parts of the onboard stack: small typed protocols a user's own code implements.

The built-ins are just the first implementations: :class:`nav.stereo.SadStereo` (MER SAD stereo),
:class:`nav.vo.VisualOdometry` (MER visual odometry) and :class:`nav.gestalt.GestaltPlanner` (GESTALT).
A scenario or the command line names an implementation by import path (``"mypkg.vo:MyVO"``) or by an entry point
registered under the group ``rover_sim.plugins``; the simulator calls it only through these methods and checks
every result with the ``check_*`` functions below, so a malformed answer stops the run with an error naming the
plugin and the field.

Frames and units (as everywhere in ``nav``): rover frame x forward, y left, z up; camera frames OpenCV (x right,
y down, z forward); metres, radians, 4x4 homogeneous transforms ``T_a_b`` mapping frame-b coordinates into a.
Images are rectified greyscale ``uint8`` arrays (H, W); ``rig`` is the calibrated stereo model flight software
holds (:class:`nav.camera.StereoRig`), never the simulator's truth.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from nav.camera import StereoRig
    from nav.gestalt import Arc, Decision
    from nav.globalloc import GlobalLocResult, OrbitalMap, PanoramaView
    from nav.vo import VoResult

# the built-in statuses; a plugin may use its own refusal strings
VO_STATUSES = ("ok", "first_frame", "reinit", "too_few_features", "no_convergence", "sanity_failed")


class PluginContractError(ValueError):
    """A plugin returned something outside its protocol; ``field`` names the offending part of the result."""

    def __init__(self, field: str, problem: str) -> None:
        self.field, self.problem = field, problem
        super().__init__(f"{field}: {problem}")


@runtime_checkable
class StereoMatcher(Protocol):
    """Dense stereo on a rectified pair (the paper's correlation step, seed 001 section 3).

    ``disparity`` returns float32 (H, W) disparities in pixels, left image as reference (``u_right = u_left - d``),
    NaN where no trustworthy match was found. Nothing else is assumed: the simulator triangulates with ``rig``.
    """

    def disparity(self, left_u8: np.ndarray, right_u8: np.ndarray, rig: StereoRig) -> np.ndarray: ...


@runtime_checkable
class VisualOdometer(Protocol):
    """Frame-to-frame stereo visual odometry, one :meth:`step` per stereo pair (MER VO, seed 000 section 2).

    ``step`` returns a :class:`nav.vo.VoResult`; the fields the simulator reads are:

    - ``status`` (str): ``"ok"`` for an accepted update; ``"first_frame"``/``"reinit"`` when the pair only
      (re)initialises; any other string is a refusal (the dead-reckoned pose stands), e.g. ``"too_few_features"``.
    - ``motion_rover`` (4x4 float, required when ``status == "ok"``): pose of the current rover frame in the previous
      one (the rover's motion between the two pairs), rotation orthonormal, translation in metres.
    - ``covariance`` (6x6 float or None): over (dx, dy, dz [m], dtheta [rad]) in the previous rover frame;
      symmetric, finite. None means "no covariance".
    - ``n_inliers`` (int >= 0) and ``reason`` (str, why a step was refused).
    - ``tracks``/``inliers`` (optional): feature tracks for the recording; ``None`` is fine.

    ``predicted_motion_rover`` is the dead-reckoned motion since the previous pair (same convention as
    ``motion_rover``); ``R_world_rover`` the IMU attitude at the previous pair. ``reset`` forgets the previous pair.

    Optional keyword ``feature_mask``: if ``step`` declares a ``feature_mask`` parameter (or ``**kwargs``), the
    simulator passes a bool (H, W) image, False where no feature should be picked: in and near the rover's own
    predicted shadow and on the rover's hardware (:mod:`nav.vo.shadow`). A ``step`` without it is
    called exactly as above and never sees the mask.

    The camera model may change between two pairs (texture-seeking mast pointing): ``rig`` is always the current
    pair's calibrated model, and an implementation must keep the previous pair's features in a frame that does
    not depend on it (the rover frame, as the built-in does).
    """

    def reset(self) -> None: ...

    def step(
        self,
        left_u8: np.ndarray,
        right_u8: np.ndarray,
        rig: StereoRig,
        predicted_motion_rover: np.ndarray | None = None,
        R_world_rover: np.ndarray | None = None,
    ) -> VoResult: ...


@runtime_checkable
class Planner(Protocol):
    """A local hazard-avoidance planner (GESTALT, seed 001 section 4): one :meth:`step` per imaging cycle.

    ``points_world`` (N, 3) are terrain points from stereo placed with the onboard pose; ``pose_xy_yaw`` the onboard
    pose (x, y [m], yaw [rad]); ``goal_xy`` the waypoint. The :class:`nav.gestalt.Decision` it returns carries
    ``arc`` (a :class:`nav.gestalt.Arc` from ``arcs``, or None to stop), ``reason`` and, for the recording, the
    goodness ``window`` and ``votes``; ``drive_m`` (optional) overrides the step length. ``arcs`` lists the
    candidate arcs (for drawing).
    """

    arcs: list[Arc]

    def step(self, points_world: np.ndarray, pose_xy_yaw: np.ndarray, goal_xy: np.ndarray) -> Decision: ...


@runtime_checkable
class GlobalLocalizer(Protocol):
    """Global localisation at a stop against orbital products (Mars 2020's Mars Global Localization; Li et al.'s
    rocks as the common features): one :meth:`localize` per navcam panorama.

    ``views`` are the panorama's rectified pairs, each with its calibrated rig (:class:`nav.globalloc.PanoramaView`);
    ``R_world_rover`` the onboard attitude (IMU roll and pitch, the onboard yaw); ``prior_xy_yaw`` the onboard pose
    (x, y [m], yaw [rad]) and ``prior_covariance`` its 3x3 uncertainty; ``orbital`` the orthoimage and DEM with their
    stated error model (:class:`nav.globalloc.OrbitalMap`). The result (:class:`nav.globalloc.GlobalLocResult`):

    - ``status`` (str): ``"ok"`` for a fix; any other string is a refusal (the onboard pose stands) with a ``reason``.
    - ``xy_yaw`` (3 floats, required when ``status == "ok"``): the fix in the map frame.
    - ``covariance`` (3x3, required when ``status == "ok"``): symmetric, positive semi-definite, finite.

    A refusal is always allowed; a wrong fix is the one thing a global localiser must not return.
    """

    def localize(
        self,
        views: list[PanoramaView],
        R_world_rover: np.ndarray,
        prior_xy_yaw: np.ndarray,
        prior_covariance: np.ndarray,
        orbital: OrbitalMap,
    ) -> GlobalLocResult: ...


# ------------------------------------------------------------------------------------------------------------
# Result checks (the simulator runs these on every plugin answer)
# ------------------------------------------------------------------------------------------------------------
def check_disparity(disparity: object, shape: tuple[int, int]) -> np.ndarray:
    """A (H, W) float array of the image's shape; NaN or finite values >= 0."""
    if not isinstance(disparity, np.ndarray):
        raise PluginContractError("disparity", f"expected a numpy array, got {type(disparity).__name__}")
    if disparity.shape != tuple(shape):
        raise PluginContractError("disparity", f"shape {disparity.shape}, expected the image shape {tuple(shape)}")
    if not np.issubdtype(disparity.dtype, np.floating):
        raise PluginContractError("disparity", f"dtype {disparity.dtype}, expected float (NaN where invalid)")
    if np.any(np.isinf(disparity)) or np.any(disparity[np.isfinite(disparity)] < 0):
        raise PluginContractError("disparity", "values must be >= 0 or NaN (no inf, no negative disparities)")
    return disparity


def _is_rotation(R: np.ndarray, tol: float = 1e-4) -> bool:
    return bool(np.allclose(R.T @ R, np.eye(3), atol=tol) and abs(np.linalg.det(R) - 1.0) < tol)


def check_vo_result(res: object) -> None:
    """Raise :class:`PluginContractError` unless ``res`` honours the :class:`VisualOdometer` result contract."""
    for name in ("status", "motion_rover", "covariance", "n_inliers", "reason"):
        if not hasattr(res, name):
            raise PluginContractError(name, f"the result ({type(res).__name__}) has no '{name}' attribute")
    status = res.status  # type: ignore[attr-defined]
    if not isinstance(status, str) or not status:
        raise PluginContractError("status", f"expected a non-empty string, got {status!r}")
    if not isinstance(res.n_inliers, int | np.integer) or res.n_inliers < 0:  # type: ignore[attr-defined]
        raise PluginContractError("n_inliers", f"expected an int >= 0, got {res.n_inliers!r}")  # type: ignore[attr-defined]
    if status != "ok":
        return
    M = res.motion_rover  # type: ignore[attr-defined]
    if not isinstance(M, np.ndarray) or M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise PluginContractError("motion_rover", f"expected a finite 4x4 array when status is 'ok', got {M!r:.80}")
    if not _is_rotation(M[:3, :3]) or not np.allclose(M[3], [0, 0, 0, 1]):
        raise PluginContractError(
            "motion_rover", "not a rigid transform (rotation not orthonormal or last row != 0001)"
        )
    C = res.covariance  # type: ignore[attr-defined]
    if C is not None:
        if not isinstance(C, np.ndarray) or C.shape != (6, 6) or not np.all(np.isfinite(C)):
            raise PluginContractError("covariance", "expected None or a finite 6x6 array")
        if not np.allclose(C, C.T, rtol=1e-6, atol=1e-12):
            raise PluginContractError("covariance", "not symmetric")


def check_decision(decision: object, n_arcs: int) -> None:
    """Raise :class:`PluginContractError` unless ``decision`` honours the :class:`Planner` result contract."""
    for name in ("arc", "reason"):
        if not hasattr(decision, name):
            raise PluginContractError(name, f"the decision ({type(decision).__name__}) has no '{name}' attribute")
    arc = decision.arc  # type: ignore[attr-defined]
    if arc is not None:
        for name in ("direction", "curvature_per_m", "turn_rad"):
            if not hasattr(arc, name):
                raise PluginContractError(f"arc.{name}", "the chosen arc lacks this attribute (use nav.gestalt.Arc)")
        if arc.direction not in (-1, 0, 1):
            raise PluginContractError("arc.direction", f"expected -1, 0 or 1, got {arc.direction!r}")
        if not np.isfinite(arc.curvature_per_m) or not np.isfinite(arc.turn_rad):
            raise PluginContractError("arc.curvature_per_m", "curvature and turn must be finite")
    drive = getattr(decision, "drive_m", None)
    if drive is not None and (not np.isfinite(drive) or drive <= 0 or drive > 5.0):
        raise PluginContractError("drive_m", f"expected None or 0 < drive_m <= 5 m, got {drive!r}")


def check_globalloc_result(res: object) -> None:
    """Raise :class:`PluginContractError` unless ``res`` honours the :class:`GlobalLocalizer` result contract."""
    for name in ("status", "reason", "xy_yaw", "covariance"):
        if not hasattr(res, name):
            raise PluginContractError(name, f"the result ({type(res).__name__}) has no '{name}' attribute")
    status = res.status  # type: ignore[attr-defined]
    if not isinstance(status, str) or not status:
        raise PluginContractError("status", f"expected a non-empty string, got {status!r}")
    if status != "ok":
        return
    xy = res.xy_yaw  # type: ignore[attr-defined]
    if not isinstance(xy, np.ndarray) or xy.shape != (3,) or not np.all(np.isfinite(xy)):
        raise PluginContractError("xy_yaw", f"expected 3 finite floats when status is 'ok', got {xy!r:.80}")
    C = res.covariance  # type: ignore[attr-defined]
    if not isinstance(C, np.ndarray) or C.shape != (3, 3) or not np.all(np.isfinite(C)):
        raise PluginContractError("covariance", "expected a finite 3x3 array when status is 'ok'")
    if not np.allclose(C, C.T, rtol=1e-6, atol=1e-12) or np.linalg.eigvalsh(0.5 * (C + C.T)).min() < -1e-12:
        raise PluginContractError("covariance", "not symmetric positive semi-definite")
