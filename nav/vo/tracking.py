"""Steps 1-5 of the MER visual odometry (Cheng, Maimone, Matthies 2005, section 2) on feature frames: one stereo
pair's features with their 3D positions and covariances (:func:`build_feature_frame`, steps 1-4) and their
"Feature Tracking" into the next pair with the dead-reckoning prediction (:func:`track_features`, step 5),
correlating templates warped through the predicted motion (:func:`warped_templates`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from nav.camera import PinholeCamera, StereoRig
from nav.geometry import se3_inv
from nav.vo.features import (
    WindowStats,
    correlate_window,
    detect_features,
    stereo_match_features,
    window_at,
    window_stats,
)
from nav.vo.motion import (
    feature_covariance,
    gap_test,
    triangulate_stereo,
)
from nav.vo.params import VoParams


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
    uv_t, cov_t = _track_left(prev, predicted_motion_rover, uv_pred, new_left, params, rig.left)
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
    prev: FeatureFrame,
    predicted_motion_rover: np.ndarray,
    uv_pred: np.ndarray,
    new_left: WindowStats,
    params: VoParams,
    new_cam: PinholeCamera | None = None,
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
            templates = warped_templates(
                prev, src.img, scale, predicted_motion_rover, uv_pred, params.window_px, idx, new_cam
            )
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
    new_cam: PinholeCamera | None = None,
) -> dict[int, np.ndarray | None]:
    """Previous left windows resampled as they should look in the new left image (view-change compensation).

    Each feature is assumed to lie on a local plane parallel to the rover's base (the ground) through its 3D
    position; with the predicted motion that plane induces the homography ``H = K (R + t n^T / d) K^-1`` from
    the previous to the new left image. Template pixel ``(j, i)`` is the previous image at
    ``H^-1(uv_pred + (j, i) / scale)``, so the template centre is the feature itself. ``img`` is the previous
    left image at resolution ``scale`` (1, or 0.5 for the pyrDown level; template pixels are pixels of that
    level); ``which`` selects features (default all); ``new_cam`` is the current left camera when the mast was
    repointed between the pairs (default: the previous one). Not in the paper (MER correlated unwarped windows); it
    keeps the near field trackable when a step changes the scale of the ground by 20-30 %.
    """
    cam = prev.rig.left
    new_cam = cam if new_cam is None else new_cam
    K, Kinv = new_cam.K, np.linalg.inv(cam.K)
    T_cam_rover = se3_inv(cam.T_rover_cam)
    # previous cam -> new cam coordinates (the new camera may point elsewhere: texture-seeking pointing)
    T_cc = se3_inv(new_cam.T_rover_cam) @ se3_inv(predicted_motion_rover) @ cam.T_rover_cam
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
