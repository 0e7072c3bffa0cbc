"""The MER visual odometry (Cheng, Maimone, Matthies 2005) one stereo pair at a time: :class:`VisualOdometry`,
whose :meth:`~VisualOdometry.step` runs the paper's steps 1-9 in order (see :mod:`nav.vo`), with the failure
handling (step 9) and the robustness guards, and its :class:`VoResult`.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np

from nav.camera import StereoRig
from nav.geometry import se3_inv
from nav.vo.features import (
    window_stats,
)
from nav.vo.motion import (
    RansacResult,
    ml_refine,
    motion_from_RT,
    motion_magnitude,
    ransac_motion,
    sanity_check,
)
from nav.vo.params import SanityConstraints, VoParams
from nav.vo.tracking import FeatureFrame, FeatureTracks, build_feature_frame, track_features

VoStatus = Literal["ok", "too_few_features", "no_convergence", "sanity_failed", "reinit", "first_frame"]


# ------------------------------------------------------------------------------------------------------------
# The pipeline
# ------------------------------------------------------------------------------------------------------------
@dataclass
class VoResult:
    """Outcome of one VO step. ``motion_rover``/``covariance`` are None unless ``status == "ok"``."""

    status: VoStatus
    motion_rover: np.ndarray | None = None  # 4x4 pose of the current rover frame in the previous rover frame
    covariance: np.ndarray | None = None  # 6x6 over (dt [m], dtheta [rad]) in the previous rover frame
    n_features: int = 0  # 3D features available in the previous frame
    n_tracked: int = 0
    n_inliers: int = 0
    reason: str = ""
    tracks: FeatureTracks | None = None  # for logging
    inliers: np.ndarray | None = None  # (len(tracks),) bool
    new_features_uv: np.ndarray | None = None  # (N, 2) features detected in the current left image
    timings_ms: dict[str, float] = field(default_factory=dict)
    failure_limit_reached: bool = False

    @property
    def ok(self) -> bool:
        return self.status == "ok"


class VisualOdometry:
    """Frame-to-frame stereo VO; one :meth:`step` per stereo pair. Holds only the previous pair's features."""

    def __init__(self, params: VoParams | None = None, constraints: SanityConstraints | None = None) -> None:
        self.params = params or VoParams()
        self.constraints = constraints or SanityConstraints()
        self._frame: FeatureFrame | None = None
        self.consecutive_failures = 0

    def reset(self) -> None:
        self._frame = None
        self.consecutive_failures = 0

    def step(
        self,
        left_u8: np.ndarray,
        right_u8: np.ndarray,
        rig: StereoRig,
        predicted_motion_rover: np.ndarray | None = None,
        R_world_rover: np.ndarray | None = None,
        feature_mask: np.ndarray | None = None,
    ) -> VoResult:
        """Estimate the rover motion since the previous pair.

        ``predicted_motion_rover``: dead-reckoned pose of the current rover frame in the previous one
        (identity if None). ``R_world_rover``: attitude at the previous pair (IMU); gives the site frame and
        the downslope direction for the sanity constraints. ``feature_mask``: bool image, False where no
        feature may be picked (rover hardware, a predicted shadow).
        """
        p, clock = self.params, _Clock()
        pred = np.eye(4) if predicted_motion_rover is None else np.asarray(predicted_motion_rover, dtype=float)
        with clock("preprocess"):
            left = window_stats(left_u8, p.window_px, coarse=p.track_coarse_search_radius_px > 0)
            right = window_stats(right_u8, p.window_px)
        prev, reinit = self._frame, self._reinit_reason(self._frame, pred, rig)
        if prev is not None and not reinit:
            with clock("track"):
                tracks = track_features(prev, pred, left, right, rig, p)  # 5. tracking
        with clock("features"):
            self._frame = build_feature_frame(left, right, rig, p, feature_mask)  # 1.-4. for the next step
        if prev is None or reinit:  # 9. nothing to compare with: (re-)initialise
            return self._finish(VoResult("first_frame" if prev is None else "reinit", reason=reinit), clock)
        res = VoResult("ok", n_features=len(prev), n_tracked=len(tracks), tracks=tracks)
        try:
            self._estimate_motion(res, tracks, pred, R_world_rover, rig, clock)  # 6.-8.
        except _Rejected as rej:  # 9. failure: no update, dead reckoning stands
            return self._finish(self._fail(res, rej.status, rej.reason), clock)
        self.consecutive_failures = 0
        return self._finish(res, clock)

    def _estimate_motion(
        self,
        res: VoResult,
        tracks: FeatureTracks,
        pred: np.ndarray,
        R_world_rover: np.ndarray | None,
        rig: StereoRig,
        clock: _Clock,
    ) -> None:
        """Steps 6-8 and the guards; fills ``res`` or raises :class:`_Rejected`."""
        p = self.params
        _require(
            res.n_features >= p.min_features,
            "too_few_features",
            f"{res.n_features} features in previous frame",
        )
        _require(len(tracks) >= p.min_features, "too_few_features", f"{len(tracks)} tracked")
        with clock("ransac"):
            rs = ransac_motion(  # 6. robust motion
                tracks.points_prev, tracks.points_cur, tracks.cov_prev, tracks.cov_cur,
                tracks.uv_cur_left, tracks.uv_cur_right, rig, p,
            )  # fmt: skip
            res.n_inliers = rs.n_inliers
            _require(rs.n_inliers >= p.min_inliers, "no_convergence", f"{rs.n_inliers} RANSAC inliers")
            rs, res.reason = self._one_motion_in_view(tracks, rs, rig)  # guard (Sol 235)
        with clock("ml"):
            idx = np.flatnonzero(rs.inliers)
            ml = ml_refine(  # 7. maximum likelihood
                tracks.points_prev[idx], tracks.points_cur[idx], tracks.cov_prev[idx], tracks.cov_cur[idx],
                rs.R, rs.T, p,
            )  # fmt: skip
        res.inliers = np.zeros(len(tracks), bool)
        res.inliers[idx[ml.inliers]] = True
        res.n_inliers = int(res.inliers.sum())
        _require(ml.converged and res.n_inliers >= p.min_inliers, "no_convergence", f"ML: {res.n_inliers} inliers")
        motion, cov = motion_from_RT(ml.R, ml.T, ml.covariance)
        self._check_solution(tracks, res.inliers, cov, rig)  # guards (Sols 137/141, uncertainty)
        ok, why = sanity_check(motion, pred, self.constraints, R_world_rover)  # 8. sanity constraints
        _require(ok, "sanity_failed", why)
        res.motion_rover, res.covariance = motion, cov

    # --- step 9 and the robustness guards -----------------------------------------------------------------
    def _reinit_reason(self, prev: FeatureFrame | None, pred: np.ndarray, rig: StereoRig) -> str:
        """Why the step must re-initialise (paper section 4: > 75 cm or > 18 deg, or a repointed camera)."""
        if prev is None:
            return ""
        t, a = motion_magnitude(pred)
        if t > self.params.reinit_max_translation_m:
            return f"predicted step {t:.2f} m > {self.params.reinit_max_translation_m} m"
        if np.degrees(a) > self.params.reinit_max_rotation_deg:
            return f"predicted turn {np.degrees(a):.1f} deg > {self.params.reinit_max_rotation_deg} deg"
        # A repointed mast (texture-seeking pointing) is fine while the views still overlap: the previous features
        # live in the rover frame and are projected with the current rig. A larger repointing re-initialises.
        same_cams = np.allclose(prev.rig.left.K, rig.left.K) and abs(prev.rig.baseline_m - rig.baseline_m) < 1e-6
        R_rel = prev.rig.left.T_rover_cam[:3, :3].T @ rig.left.T_rover_cam[:3, :3]
        turn = np.degrees(np.arccos(np.clip((np.trace(R_rel) - 1.0) / 2.0, -1.0, 1.0)))
        if not same_cams or turn > self.params.max_repoint_deg:
            return f"camera repointed by {turn:.1f} deg (> {self.params.max_repoint_deg} deg)"
        return ""

    def _one_motion_in_view(self, tracks: FeatureTracks, rs: RansacResult, rig: StereoRig) -> tuple[RansacResult, str]:
        """Guard: two rigid motions in view (e.g. terrain and the rover's own shadow, Sol 235).

        A second RANSAC runs on the features the best motion rejects. A consensus of at least
        ``ambiguity_ratio`` of the best one (and ``min_inliers``) that moves differently makes the step
        ambiguous: refused, unless ``resolve_rover_fixed_consensus`` is set and exactly one consensus is fixed
        to the rover (its features barely move under their own motion, less than a quarter of what the other
        motion would move them); then those features are dropped and RANSAC re-run. Returns the consensus to
        refine and a note.
        """
        p = self.params
        rest = np.flatnonzero(~rs.inliers)
        need = max(p.min_inliers, int(np.ceil(p.ambiguity_ratio * rs.n_inliers)))
        if len(rest) < need:
            return rs, ""
        rs2 = _ransac_subset(tracks, rest, rig, p, seed_offset=1)
        M1, M2 = motion_from_RT(rs.R, rs.T)[0], motion_from_RT(rs2.R, rs2.T)[0]
        dt, da = motion_magnitude(se3_inv(M1) @ M2)
        if rs2.n_inliers < need or (
            dt < p.ambiguity_min_translation_m and np.degrees(da) < p.ambiguity_min_rotation_deg
        ):
            return rs, ""
        if p.resolve_rover_fixed_consensus:
            fixed1 = _is_rover_fixed(rs, rs2, tracks, p)
            fixed2 = _is_rover_fixed(rs2, rs, tracks, p)
            if fixed1 != fixed2:
                rover_fixed = rs.inliers if fixed1 else rs2.inliers
                rs3 = _ransac_subset(tracks, np.flatnonzero(~rover_fixed), rig, p, seed_offset=2)
                if rs3.n_inliers >= p.min_inliers:
                    return rs3, f"ignored {int(rover_fixed.sum())} rover-fixed features (own shadow?)"
        raise _Rejected(
            "sanity_failed",
            f"ambiguous: a second consensus of {rs2.n_inliers} (best {rs.n_inliers}) moves {dt:.3f} m apart",
        )

    def _check_solution(self, tracks: FeatureTracks, inliers: np.ndarray, cov: np.ndarray, rig: StereoRig) -> None:
        """Guards: inlier spread over the image (Sols 137/141), inlier fraction, solution covariance."""
        p = self.params
        uv = tracks.uv_cur_left[inliers]
        w, h, g = rig.left.width_px, rig.left.height_px, p.spread_grid_cells
        cell = np.clip((uv[:, 1] * g / h).astype(int), 0, g - 1) * g + np.clip((uv[:, 0] * g / w).astype(int), 0, g - 1)
        n_cells = len(np.unique(cell))
        _require(n_cells >= p.min_inlier_cells, "sanity_failed", f"inliers clustered in {n_cells} of {g * g} cells")
        hull = float(cv2.contourArea(cv2.convexHull(uv.astype(np.float32)))) / (w * h)
        _require(hull >= p.min_inlier_hull_fraction, "sanity_failed", f"inliers clustered: hull {100 * hull:.1f} %")
        _require(
            inliers.sum() >= p.min_inlier_fraction * len(tracks),
            "sanity_failed",
            f"only {inliers.sum()} of {len(tracks)} tracked features are inliers",
        )
        sig_t = float(np.sqrt(np.max(np.linalg.eigvalsh(cov[:3, :3]))))
        sig_r = float(np.degrees(np.sqrt(np.max(np.linalg.eigvalsh(cov[3:, 3:])))))
        _require(
            sig_t <= p.max_translation_sigma_m and sig_r <= p.max_rotation_sigma_deg,
            "sanity_failed",
            f"solution too uncertain: sigma {sig_t:.3f} m, {sig_r:.2f} deg",
        )

    def _fail(self, res: VoResult, status: VoStatus, reason: str) -> VoResult:
        res.status, res.reason = status, reason
        res.motion_rover = res.covariance = None
        self.consecutive_failures += 1
        lim = self.constraints.max_failures
        res.failure_limit_reached = lim is not None and self.consecutive_failures > lim
        return res

    def _finish(self, res: VoResult, clock: _Clock) -> VoResult:
        if self._frame is not None:
            res.new_features_uv = self._frame.uv_left
        res.timings_ms = dict(clock.ms)
        res.timings_ms["total"] = sum(clock.ms.values())
        return res


class _Rejected(Exception):
    """Internal: a step ends without an update (step 9)."""

    def __init__(self, status: VoStatus, reason: str) -> None:
        super().__init__(reason)
        self.status, self.reason = status, reason


def _require(cond: bool, status: VoStatus, reason: str) -> None:
    if not cond:
        raise _Rejected(status, reason)


def _is_rover_fixed(a: RansacResult, b: RansacResult, tracks: FeatureTracks, p: VoParams) -> bool:
    """Consensus ``a`` barely moves its own features compared with what motion ``b`` would do to them."""
    own, other = _displacement(a, tracks, a.inliers), _displacement(b, tracks, a.inliers)
    return own < 0.25 * other and other > p.ambiguity_min_translation_m


def _displacement(rs: RansacResult, tracks: FeatureTracks, sel: np.ndarray) -> float:
    """Median distance the motion ``rs`` moves the selected previous features (m)."""
    P = tracks.points_prev[sel]
    return float(np.median(np.linalg.norm(P @ rs.R.T + rs.T - P, axis=1)))


def _ransac_subset(
    tracks: FeatureTracks, idx: np.ndarray, rig: StereoRig, p: VoParams, seed_offset: int
) -> RansacResult:
    """RANSAC on the tracks ``idx``; the result's inlier mask refers to all tracks."""
    rs = ransac_motion(
        tracks.points_prev[idx], tracks.points_cur[idx], tracks.cov_prev[idx], tracks.cov_cur[idx],
        tracks.uv_cur_left[idx], tracks.uv_cur_right[idx], rig, p,
        rng=np.random.default_rng(p.ransac_seed + seed_offset),
    )  # fmt: skip
    inl = np.zeros(len(tracks), bool)
    inl[idx[rs.inliers]] = True
    err = np.full(len(tracks), np.inf)
    err[idx] = rs.error_px
    return RansacResult(rs.R, rs.T, inl, rs.n_inliers, err)


class _Clock:
    """Wall-clock time per named stage (ms)."""

    def __init__(self) -> None:
        self.ms: dict[str, float] = {}

    @contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.ms[name] = self.ms.get(name, 0.0) + 1e3 * (time.perf_counter() - t0)
