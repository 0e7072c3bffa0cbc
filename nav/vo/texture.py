"""Trackable texture and view overlap, for texture-seeking mast pointing before a VO step.

MER's drivers pointed the navcams at textured ground (rocks, outcrop edges, the rover's own tracks) for VO. The
onboard side does it here from its own data: :func:`trackable_points` counts the features VO could use in a pair
(steps 1-4: corners that stereo-match and triangulate, outside the predicted shadow); :func:`view_overlap`
predicts how much of a candidate view shows ground the previous pair saw (the ground plane, the dead-reckoned
motion and both calibrated camera models); :func:`points_in_view` counts features of one view that fall in
another. Pure numpy/OpenCV.
"""

from __future__ import annotations

import numpy as np

from nav.camera import PinholeCamera, StereoRig
from nav.geometry import se3_inv
from nav.vo.features import window_stats
from nav.vo.params import VoParams
from nav.vo.tracking import build_feature_frame

MIN_OVERLAP = 0.60  # paper section 4: VO needs >= 60 % overlap between consecutive pairs


def trackable_points(
    left_u8: np.ndarray, right_u8: np.ndarray, rig: StereoRig, params: VoParams, mask: np.ndarray | None = None
) -> np.ndarray:
    """(N, 3) rover-frame positions of the features VO's steps 1-4 find in this pair (``mask``: False = barred)."""
    left = window_stats(left_u8, params.window_px)
    right = window_stats(right_u8, params.window_px)
    return build_feature_frame(left, right, rig, params, mask).points_rover


def points_in_view(points_rover: np.ndarray, cam: PinholeCamera, T_view_points: np.ndarray, border_px: int = 8) -> int:
    """How many of ``points_rover`` (rover frame A) land inside ``cam``'s image, ``cam`` mounted on rover frame B
    with ``T_view_points`` the pose of A in B."""
    if len(points_rover) == 0:
        return 0
    P = points_rover @ T_view_points[:3, :3].T + T_view_points[:3, 3]
    T = se3_inv(cam.T_rover_cam)
    Pc = P @ T[:3, :3].T + T[:3, 3]
    front = Pc[:, 2] > 0.05
    uv = cam.project(Pc[front]) if front.any() else np.zeros((0, 2))
    inside = (
        (uv[:, 0] >= border_px)
        & (uv[:, 0] <= cam.width_px - 1 - border_px)
        & (uv[:, 1] >= border_px)
        & (uv[:, 1] <= cam.height_px - 1 - border_px)
    )
    return int(inside.sum())


def view_overlap(
    prev_cam: PinholeCamera, cur_cam: PinholeCamera, motion_prev_cur: np.ndarray, ground_z_m: float, grid: int = 16
) -> float:
    """Fraction of ``cur_cam``'s ground view that ``prev_cam`` saw: pixels on a ``grid`` x ``grid`` lattice are cast
    onto the ground plane (rover-frame height ``ground_z_m``), moved into the previous rover frame with
    ``motion_prev_cur`` (pose of the current rover frame in the previous one) and projected into ``prev_cam``."""
    u = np.linspace(0, cur_cam.width_px - 1, grid)
    uu, vv = np.meshgrid(u, np.linspace(0, cur_cam.height_px - 1, grid))
    d = np.stack([(uu - cur_cam.cx_px) / cur_cam.fx_px, (vv - cur_cam.cy_px) / cur_cam.fy_px, np.ones_like(uu)], -1)
    R, c = cur_cam.T_rover_cam[:3, :3], cur_cam.T_rover_cam[:3, 3]
    d = d.reshape(-1, 3) @ R.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ground_z_m - c[2]) / d[:, 2]
    ok = np.isfinite(t) & (t > 0) & (t < 30.0)
    if not ok.any():
        return 0.0
    g = c + d[ok] * t[ok, None]
    return points_in_view(g, prev_cam, motion_prev_cur, border_px=0) / float(ok.sum())
