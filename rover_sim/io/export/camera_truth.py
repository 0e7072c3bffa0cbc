"""Ground truth in the exported images' frame: the true pose of the camera a *rectified* image is.

On the flight profile the cameras form raw images through their true lenses and mountings, and the onboard stack
rectifies them with its *calibrated* models (:mod:`nav.rectify`): each rectified pixel ``(u, v)`` of the rectified
pinhole ``K`` is the raw pixel that the calibrated model assigns to the ray ``K^-1 (u, v, 1)`` turned into the
calibrated raw frame. The light that reached that raw pixel truly came along the *true* model's ray of the pixel.
The rectified image is therefore a pinhole image taken from the true optical centre with an orientation that
differs from the physical camera's by the mounting rotation, the rectifying rotation and the calibration's
pointing and principal-point errors (0.1-0.2 deg on the flight profile), plus a small non-rigid residual
(focal-length and distortion errors, which no pose can absorb).

:func:`true_rectified_pose` computes that pose: the rotation is the least-squares fit (Wahba's problem, solved
by SVD as in Markley 1988) between the rectified rays of a grid of pixels and the true rays of the raw pixels the
rectification maps them to; the position is the true optical centre. The exporter is an evaluator-side listener:
it reads the true models; nothing onboard does.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from nav.camera import PinholeCamera
from nav.lens import CameraModel

GRID_STEPS = 17  # rectified pixels per side of the fitting grid (17 x 17 = 289 rays, edge to edge)


def rectified_rays(cam: PinholeCamera, steps: int = GRID_STEPS) -> tuple[np.ndarray, np.ndarray]:
    """A grid of pixel centres of ``cam`` (N x 2, edge to edge) and their unit rays in its frame (N x 3)."""
    u, v = np.meshgrid(np.linspace(0.0, cam.width_px - 1.0, steps), np.linspace(0.0, cam.height_px - 1.0, steps))
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    rays = np.stack([(uv[:, 0] - cam.cx_px) / cam.fx_px, (uv[:, 1] - cam.cy_px) / cam.fy_px, np.ones(len(uv))], 1)
    return uv, rays / np.linalg.norm(rays, axis=1, keepdims=True)


def raw_pixels(rect_cam: PinholeCamera, calibrated: CameraModel, rays_rect: np.ndarray) -> np.ndarray:
    """The raw pixels the rectification maps rectified rays to: the rays turned into the calibrated raw frame and
    projected by the calibrated model (what :func:`nav.rectify.rectify_table` tabulates)."""
    R_raw_rect = calibrated.T_rover_cam[:3, :3].T @ rect_cam.T_rover_cam[:3, :3]
    return calibrated.project(rays_rect @ R_raw_rect.T)


def true_rectified_pose(rect_cam: PinholeCamera, calibrated: CameraModel, true: CameraModel) -> np.ndarray:
    """``T_rover_cam`` of the camera whose image is ``rect_cam``'s rectified image, when the raw camera truly is
    ``true`` and was rectified through ``calibrated`` (both raw models with their ``T_rover_cam``).

    Rotation: the least-squares rotation taking the rectified rays of a pixel grid onto the true rays (rover
    frame) of the raw pixels they come from; position: ``true``'s optical centre. Equal to ``rect_cam``'s pose
    when ``calibrated`` is ``true`` (an exact calibration)."""
    _, rays = rectified_rays(rect_cam)
    raw = raw_pixels(rect_cam, calibrated, rays)
    inside = np.all(np.isfinite(raw), axis=1)
    d = true.unproject(raw[inside]) @ true.T_rover_cam[:3, :3].T  # the true rays, rover frame
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    R, _ = Rotation.align_vectors(d, rays[inside])
    T = np.eye(4)
    T[:3, :3] = R.as_matrix()
    T[:3, 3] = true.T_rover_cam[:3, 3]
    return T


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle of the rotation between two orientations (degrees)."""
    return float(np.degrees(Rotation.from_matrix(np.asarray(R_a)[:3, :3].T @ np.asarray(R_b)[:3, :3]).magnitude()))
