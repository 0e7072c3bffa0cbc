"""Stereo visual odometry as flown on the Mars Exploration Rovers (Cheng, Maimone, Matthies 2005).

:meth:`VisualOdometry.step` reads as the paper's list:

1. feature detection (Harris, grid, minimum spacing)  -> :func:`nav.vo_features.detect_features`
2. stereo matching (pseudo-normalised correlation)    -> :func:`nav.vo_features.stereo_match_features`
3. triangulation with a gap test                      -> :func:`nav.vo_motion.triangulate_rays`
4. covariance per feature                             -> :func:`nav.vo_motion.feature_covariance`
5. tracking with the dead-reckoning prediction        -> :func:`track_features`
6. RANSAC over weighted closed-form least squares     -> :func:`nav.vo_motion.ransac_motion`
7. maximum-likelihood refinement                      -> :func:`nav.vo_motion.ml_refine`
8. sanity constraints                                 -> :func:`nav.vo_motion.sanity_check`
9. failure handling: no update, the dead-reckoned motion stands; over-large steps re-initialise.

Frames: features live in the rover frame of their image (``rig.left.T_rover_cam`` places the cameras). The
result ``motion_rover`` is the pose of the current rover frame in the previous one, the same convention as the
``predicted_motion_rover`` from dead reckoning.

Robustness guards added to the paper's checks (all in :class:`~nav.vo_params.VoParams`), motivated by its
section 4.3 false positives: inliers must spread over the image (Sols 137/141, features clustered on one flat
patch); a second, different consensus among the rejected features means two rigid motions are in view, such as
the terrain and the rover's own shadow (Sol 235), and the step is refused; a solution whose covariance is too
large is refused. Declining an update costs only the dead-reckoning error of one step; a false update can be
far worse.
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
    WindowStats,
    correlate_window,
    detect_features,
    fit_biquadratic_peak,
    pseudo_normalized_correlation,
    stereo_match_features,
    window_at,
    window_stats,
)
from nav.vo.motion import (
    RansacResult,
    downslope_direction,
    feature_covariance,
    gap_test,
    ml_refine,
    motion_from_RT,
    motion_magnitude,
    ransac_motion,
    reprojection_error_px,
    sanity_check,
    triangulate_rays,
    triangulate_stereo,
)
from nav.vo.params import SanityConstraints, VoParams

__all__ = [
    "FeatureFrame",
    "FeatureTracks",
    "SanityConstraints",
    "VisualOdometry",
    "VoParams",
    "VoResult",
    "VoStatus",
    "build_feature_frame",
    "detect_features",
    "downslope_direction",
    "feature_covariance",
    "fit_biquadratic_peak",
    "ml_refine",
    "pseudo_normalized_correlation",
    "ransac_motion",
    "reprojection_error_px",
    "sanity_check",
    "stereo_match_features",
    "track_features",
    "triangulate_rays",
    "triangulate_stereo",
]

VoStatus = Literal["ok", "too_few_features", "no_convergence", "sanity_failed", "reinit", "first_frame"]


# ------------------------------------------------------------------------------------------------------------
# Steps 1-4 on one stereo pair
# ------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FeatureFrame:
    """Features of one stereo pair with their 3D positions and covariances in that image's rover frame."""

    left: WindowStats
    right: WindowStats
    rig: StereoRig
    uv_left: np.ndarray  # (N, 2) integer pixel positions of the detected corners
    uv_right: np.ndarray  # (N, 2) sub-pixel stereo matches
    points_rover: np.ndarray  # (N, 3)
    cov_rover: np.ndarray  # (N, 3, 3)
    n_detected: int

    def __len__(self) -> int:
        return len(self.uv_left)


def build_feature_frame(
    left: WindowStats, right: WindowStats, rig: StereoRig, params: VoParams, mask: np.ndarray | None = None
) -> FeatureFrame:
    """Steps 1-4: detect corners, match them in the right image, triangulate (gap test), covariance."""
    uv = detect_features(left.img, params, mask)  # 1
    st = stereo_match_features(left, right, uv, params)  # 2
    uv_l, uv_r = st.uv_left[st.valid], st.uv_right[st.valid]
    tri = triangulate_stereo(rig, uv_l, uv_r)  # 3
    ok = gap_test(tri, rig, params.max_ray_gap_px, params.max_range_m)
    cov = feature_covariance(rig, uv_l[ok], uv_r[ok], st.cov_left_px2[st.valid][ok], st.cov_right_px2[st.valid][ok])
    return FeatureFrame(left, right, rig, uv_l[ok], uv_r[ok], tri.points[ok], cov, len(uv))  # 4


# ------------------------------------------------------------------------------------------------------------
# Step 5: tracking
# ------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FeatureTracks:
    """Features of the previous frame found again in the current pair (step 5 output)."""

    prev_index: np.ndarray  # (M,) index into the previous FeatureFrame
    uv_prev_left: np.ndarray  # (M, 2)
    uv_predicted: np.ndarray  # (M, 2) where dead reckoning predicted them in the current left image
    uv_cur_left: np.ndarray  # (M, 2)
    uv_cur_right: np.ndarray  # (M, 2)
    points_prev: np.ndarray  # (M, 3) previous rover frame
    cov_prev: np.ndarray  # (M, 3, 3)
    points_cur: np.ndarray  # (M, 3) current rover frame
    cov_cur: np.ndarray  # (M, 3, 3)

    def __len__(self) -> int:
        return len(self.prev_index)


def track_features(
    prev: FeatureFrame,
    predicted_motion_rover: np.ndarray,
    new_left: np.ndarray | WindowStats,
    new_right: np.ndarray | WindowStats,
    rig: StereoRig,
    params: VoParams,
) -> FeatureTracks:
    """Step 5: find the previous features in the new pair.

    Previous 3D features are moved by the predicted motion and projected into the new left image; a
    correlation search around each prediction (template: the previous left window warped to the predicted view,
    see :func:`warped_templates`; coarse-to-fine where the prediction is far off) gives the new sub-pixel
    position. The tracked features are
    stereo-matched again, searching only the disparities of depths within ``max_track_shift_m`` of the
    predicted 3D position; that template sits on the nearest integer pixel and the right match is shifted by the
    same fraction (locally constant disparity). New 3D positions and covariances follow (steps 3-4); features
    whose 3D position moved more than ``max_track_shift_m`` from the prediction are dropped.
    """
    if not isinstance(new_left, WindowStats):
        new_left = window_stats(new_left, params.window_px, coarse=params.track_coarse_search_radius_px > 0)
    if not isinstance(new_right, WindowStats):
        new_right = window_stats(new_right, params.window_px)
    T_cur_prev = se3_inv(predicted_motion_rover)
    P_pred = prev.points_rover @ T_cur_prev[:3, :3].T + T_cur_prev[:3, 3]
    uv_pred = rig.left.project(_to_cam(rig.left.T_rover_cam, P_pred))
    uv_t, cov_t = _track_left(prev, predicted_motion_rover, uv_pred, new_left, params)
    found = np.flatnonzero(np.isfinite(uv_t[:, 0]))
    # stereo re-match, searching only the disparities of depths within max_track_shift_m of the predicted 3D
    uv_int = np.round(uv_t[found])
    z_pred = _to_cam(rig.left.T_rover_cam, P_pred[found])[:, 2]
    fb, dz, s = rig.left.fx_px * rig.baseline_m, params.max_track_shift_m, params.track_disparity_slack_px
    z_near = np.maximum(z_pred - dz, fb / params.max_disparity_px)
    d_range = np.stack([fb / (z_pred + dz) - s, fb / z_near + s], axis=1)
    st = stereo_match_features(new_left, new_right, uv_int, params, d_range)
    found, st_valid = found[st.valid], st.valid
    uv_cl = uv_t[found]
    uv_cr = st.uv_right[st_valid] + (uv_cl - uv_int[st_valid])
    tri = triangulate_stereo(rig, uv_cl, uv_cr)
    ok = gap_test(tri, rig, params.max_ray_gap_px, params.max_range_m)
    ok &= np.linalg.norm(tri.points - P_pred[found], axis=1) <= params.max_track_shift_m
    found, uv_cl, uv_cr = found[ok], uv_cl[ok], uv_cr[ok]
    # per-image covariance: half of each match's covariance (as in step 2)
    cov_cur = feature_covariance(rig, uv_cl, uv_cr, cov_t[found] / 2.0, st.cov_right_px2[st_valid][ok])
    return FeatureTracks(
        prev_index=found,
        uv_prev_left=prev.uv_left[found],
        uv_predicted=uv_pred[found],
        uv_cur_left=uv_cl,
        uv_cur_right=uv_cr,
        points_prev=prev.points_rover[found],
        cov_prev=prev.cov_rover[found],
        points_cur=tri.points[ok],
        cov_cur=cov_cur,
    )


def _track_left(
    prev: FeatureFrame, predicted_motion_rover: np.ndarray, uv_pred: np.ndarray, new_left: WindowStats, params: VoParams
) -> tuple[np.ndarray, np.ndarray]:
    """Correlation search for each previous feature around its predicted position in the new left image.

    Two searches, the better-correlated match wins: at full resolution within ``track_search_radius_px``, and
    coarse-to-fine, ``track_coarse_search_radius_px`` on the half-resolution images then
    ``track_refine_radius_px`` at full resolution (for predictions far off, e.g. heavy slip; weak fine texture
    may not survive the half resolution, hence both). Returns sub-pixel positions (NaN where lost) and the
    covariances of the full-resolution matches.
    """
    n = len(prev)
    predicted = np.flatnonzero(np.isfinite(uv_pred[:, 0]))

    def search(src: WindowStats, dst: WindowStats, scale: float, centre: np.ndarray, idx: np.ndarray, r: int):
        uv, cov, score = np.full((n, 2), np.nan), np.full((n, 2, 2), np.nan), np.full(n, -np.inf)
        if params.track_warp_templates:
            templates = warped_templates(prev, src.img, scale, predicted_motion_rover, uv_pred, params.window_px, idx)
        else:
            templates = {k: window_at(src.img, prev.uv_left[k] * scale, params.window_px) for k in idx}
        for k in idx:
            if templates[k] is None:
                continue
            pu, pv = int(round(centre[k, 0] * scale)), int(round(centre[k, 1] * scale))
            m = correlate_window(
                templates[k], dst, (pu - r, pu + r), (pv - r, pv + r), params, params.min_track_correlation
            )
            if m.ok:
                uv[k], cov[k], score[k] = m.uv / scale, m.cov_px2 / scale**2, m.score
        return uv, cov, score

    uv, cov, score = search(prev.left, new_left, 1.0, uv_pred, predicted, params.track_search_radius_px)
    if params.track_coarse_search_radius_px > 0 and prev.left.coarse and new_left.coarse:
        coarse = search(
            prev.left.coarse, new_left.coarse, 0.5, uv_pred, predicted, params.track_coarse_search_radius_px
        )
        found = np.flatnonzero(np.isfinite(coarse[0][:, 0]))
        uv2, cov2, score2 = search(prev.left, new_left, 1.0, coarse[0], found, params.track_refine_radius_px)
        better = score2 > score
        uv[better], cov[better] = uv2[better], cov2[better]
    return uv, cov


def warped_templates(
    prev: FeatureFrame,
    img: np.ndarray,
    scale: float,
    predicted_motion_rover: np.ndarray,
    uv_pred: np.ndarray,
    window_px: int,
    which: np.ndarray | None = None,
) -> dict[int, np.ndarray | None]:
    """Previous left windows resampled as they should look in the new left image (view-change compensation).

    Each feature is assumed to lie on a local plane parallel to the rover's base (the ground) through its 3D
    position; with the predicted motion that plane induces the homography ``H = K (R + t n^T / d) K^-1`` from
    the previous to the new left image. Template pixel ``(j, i)`` is the previous image at
    ``H^-1(uv_pred + (j, i) / scale)``, so the template centre is the feature itself. ``img`` is the previous
    left image at resolution ``scale`` (1, or 0.5 for the pyrDown level; template pixels are pixels of that
    level); ``which`` selects features (default all). Not in the paper (MER correlated unwarped windows); it
    keeps the near field trackable when a step changes the scale of the ground by 20-30 %.
    """
    cam = prev.rig.left
    K, Kinv = cam.K, np.linalg.inv(cam.K)
    T_cam_rover = se3_inv(cam.T_rover_cam)
    T_cc = T_cam_rover @ se3_inv(predicted_motion_rover) @ cam.T_rover_cam  # previous cam -> new cam coordinates
    n_cam = T_cam_rover[:3, :3] @ np.array([0.0, 0.0, 1.0])
    dist = _to_cam(cam.T_rover_cam, prev.points_rover) @ n_cam  # plane n . X = dist through each feature
    h = window_px // 2
    jj, ii = np.meshgrid(np.arange(-h, h + 1, dtype=float), np.arange(-h, h + 1, dtype=float))
    which = np.arange(len(prev)) if which is None else np.asarray(which)
    out: dict[int, np.ndarray | None] = {int(k): None for k in which}
    idx = which[np.all(np.isfinite(uv_pred[which]), axis=1) & (np.abs(dist[which]) > 1e-6)]
    if len(idx) == 0:
        return out
    Hs = K @ (T_cc[:3, :3] + T_cc[:3, 3][None, :, None] * n_cam[None, None, :] / dist[idx, None, None]) @ Kinv
    qx = uv_pred[idx, 0, None, None] + jj / scale
    qy = uv_pred[idx, 1, None, None] + ii / scale
    p = np.einsum("mij,mabj->mabi", np.linalg.inv(Hs), np.stack([qx, qy, np.ones_like(qx)], axis=-1))
    px, py = scale * p[..., 0] / p[..., 2], scale * p[..., 1] / p[..., 2]
    h_img, w_img = img.shape
    inside = (
        (px.min(axis=(1, 2)) >= 0)
        & (py.min(axis=(1, 2)) >= 0)
        & (px.max(axis=(1, 2)) <= w_img - 1)
        & (py.max(axis=(1, 2)) <= h_img - 1)
    )
    mx = px.reshape(-1, window_px).astype(np.float32)
    my = py.reshape(-1, window_px).astype(np.float32)
    warped = cv2.remap(img, mx, my, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    warped = warped.reshape(len(idx), window_px, window_px)
    for m, k in enumerate(idx):
        if inside[m]:
            out[int(k)] = warped[m]
    return out


def _to_cam(T_rover_cam: np.ndarray, P_rover: np.ndarray) -> np.ndarray:
    T = se3_inv(T_rover_cam)
    return P_rover @ T[:3, :3].T + T[:3, 3]


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
        same_rig = (
            np.allclose(prev.rig.left.T_rover_cam, rig.left.T_rover_cam, atol=1e-9)
            and np.allclose(prev.rig.right.T_rover_cam, rig.right.T_rover_cam, atol=1e-9)
            and np.allclose(prev.rig.left.K, rig.left.K)
        )
        return "" if same_rig else "camera repointed"

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
