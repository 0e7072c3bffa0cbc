"""Onboard stereo rectification from the calibrated camera models (MER's "linearisation" before stereo).

MER flight software rectified each raw pair with its CAHVOR/CAHVORE models into a pair of aligned pinhole (CAHV)
models before stereo correlation and VO (Maki et al. 2003; Goldberg, Maimone & Matthies 2002, "Stereo vision and
rover navigation software for planetary exploration"). Here: from the calibrated left/right models build

* the rectified rig (:class:`~nav.camera.StereoRig`): both cameras keep their calibrated optical centres and take a
  common orientation whose x axis runs along the calibrated baseline and whose z axis is the mean of the two
  optical axes made orthogonal to it (Fusiello, Trucco & Verri 2000); intrinsics are the given ``target`` pinhole
  (the nominal camera at the output resolution, so an error-free calibration reproduces the ideal rig), its focal
  length scaled up just enough (:func:`valid_zoom`) that every rectified pixel of both cameras sees inside its raw
  image: no black slivers along the edges where the mounting or calibrated rotation turned the view past the raw
  image (the ``alpha = 0`` choice of ``cv2.stereoRectify``; 1-4 % with the flight profile's mounting and calibration
  errors, none for a pinhole rig already aligned);
* remap tables (like ``cv2.initUndistortRectifyMap``, but through our models): for each rectified pixel, its ray
  in the rectified frame, rotated into the raw camera, projected by the calibrated model.

Row error budget of a rectified pair (the bar: <= 0.3 px on matched features; 256^2 navcam, flight
profile): the calibration's stereo relative rotation dominates (0.02 deg per axis = 0.11 px of row shift, 1 sigma);
the bilinear resampling (the simulator's render -> raw remap, then this raw -> rectified one) adds a row offset
of -0.04 to +0.07 px that depends on the maps' sub-pixel phases (exact calibrations of 6 true pairs; bicubic
rectification halves it; bilinear kept, as in JPL's VICAR ``mpfcahv`` rectification).
:func:`epipolar_row_error_px` gives the calibration's own row error at any pixel, free of matching and resampling.

Triangulating with the rectified rig *is* triangulating through the models: a rectified pixel stands for exactly
the ray its table entry's raw pixel has under the calibrated model (same optical centre, rotated only), so matches
and depths in rectified coordinates are the model rays' intersections. Calibration errors therefore enter stereo
and VO just as they did on the rover.

Tables are cached per calibration (:func:`rectification`): the hazcams keep theirs for a whole drive, the navcams
recompute after each mast repointing.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace

import cv2
import numpy as np

from nav.camera import PinholeCamera, StereoRig
from nav.lens import CahvorCamera, CameraModel

CACHE_SIZE = 16  # calibrations kept (pairs x recent pointings)
MAX_ZOOM = 1.5  # largest focal-length factor valid_zoom may apply (beyond: the models hardly overlap)
ZOOM_STEPS = 40  # bisection steps of valid_zoom (2^-40 of the search interval)


@dataclass(frozen=True)
class StereoCalibration:
    """The onboard (calibrated) models of one pair and the pinhole intrinsics wanted after rectification."""

    left: CameraModel
    right: CameraModel
    target: PinholeCamera  # intrinsics (size, fx, fy, cx, cy) of the rectified images; its pose is ignored

    @staticmethod
    def from_rig(rig: StereoRig) -> StereoCalibration:
        """A pinhole rig as distortion-free CAHVOR models (its rectified rig is ``rig`` itself)."""
        return StereoCalibration(CahvorCamera.from_pinhole(rig.left), CahvorCamera.from_pinhole(rig.right), rig.left)

    def key(self) -> str:
        """Digest of every parameter (identifies the calibration in the cache)."""
        h = hashlib.sha1()
        for obj in (self.left, self.right, self.target):
            for name, value in sorted(vars(obj).items()):
                h.update(name.encode())
                h.update(value.encode() if isinstance(value, str) else np.asarray(value, dtype=float).tobytes())
        return h.hexdigest()


@dataclass(frozen=True)
class Rectification:
    """The rectified rig and the raw -> rectified remap tables (float32, rectified image shape) of each camera."""

    rig: StereoRig
    left_map: tuple[np.ndarray, np.ndarray]
    right_map: tuple[np.ndarray, np.ndarray]

    def apply(self, left_raw: np.ndarray, right_raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectify a raw pair (bilinear; rectified pixels that see outside the raw image are 0)."""
        return remap(left_raw, self.left_map), remap(right_raw, self.right_map)


def remap(image: np.ndarray, table: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    return cv2.remap(image, table[0], table[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def rectifying_rotation(T_rover_left: np.ndarray, T_rover_right: np.ndarray) -> np.ndarray:
    """3x3 rover-frame orientation (columns x, y, z) shared by the rectified cameras (Fusiello et al. 2000)."""
    x = T_rover_right[:3, 3] - T_rover_left[:3, 3]
    x = x / np.linalg.norm(x)
    z = T_rover_left[:3, 2] + T_rover_right[:3, 2]
    z = z - (z @ x) * x
    z = z / np.linalg.norm(z)
    return np.stack([x, np.cross(z, x), z], axis=1)


def _edge_rays(target: PinholeCamera, zoom: float) -> np.ndarray:
    """(N, 3) rays (rectified frame) of the outermost pixel centres of ``target`` with its focal length x ``zoom``."""
    w, h = target.width_px, target.height_px
    u = np.concatenate([np.arange(w), np.arange(w), np.zeros(h), np.full(h, w - 1.0)]).astype(float)
    v = np.concatenate([np.zeros(w), np.full(w, h - 1.0), np.arange(h), np.arange(h)]).astype(float)
    return np.stack([(u - target.cx_px) / (zoom * target.fx_px), (v - target.cy_px) / (zoom * target.fy_px),
                     np.ones(u.size)], axis=1)  # fmt: skip


def _sees_inside(model: CameraModel, rays_rect: np.ndarray, R_rover_rect: np.ndarray) -> bool:
    """Whether every ray lands on the raw image of ``model`` within bilinear reach (0 <= u <= width - 1, ...)."""
    uv = model.project(rays_rect @ (model.T_rover_cam[:3, :3].T @ R_rover_rect).T)
    eps = 1e-6
    return bool(np.all(np.isfinite(uv)) and np.all(uv >= -eps) and np.all(uv[:, 0] <= model.width_px - 1 + eps)
                and np.all(uv[:, 1] <= model.height_px - 1 + eps))  # fmt: skip


def valid_zoom(calib: StereoCalibration, R_rover_rect: np.ndarray) -> float:
    """Smallest factor >= 1 on the target's focal length for which the edge pixels of both rectified cameras (and
    so, the raw images' outlines being star-shaped about their centres, every pixel) see inside the raw images
    (``cv2.stereoRectify`` with ``alpha = 0``). Exactly 1 when the target view already fits."""

    def fits(zoom: float) -> bool:
        rays = _edge_rays(calib.target, zoom)
        return all(_sees_inside(m, rays, R_rover_rect) for m in (calib.left, calib.right))

    if fits(1.0):
        return 1.0
    lo, hi = 1.0, MAX_ZOOM
    if not fits(hi):
        raise ValueError(f"rectification: the calibrated {calib.left.name}/{calib.right.name} views overlap too "
                         f"little for a {calib.target.width_px}x{calib.target.height_px} rectified pair "
                         f"(needs more than {MAX_ZOOM}x zoom): check the calibration's rotations")  # fmt: skip
    for _ in range(ZOOM_STEPS):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if fits(mid) else (mid, hi)
    return hi


def rectified_rig(calib: StereoCalibration) -> StereoRig:
    """The rectified pinhole rig of ``calib`` (see the module docstring)."""
    Tl, Tr = calib.left.T_rover_cam, calib.right.T_rover_cam
    R = rectifying_rotation(Tl, Tr)
    zoom = valid_zoom(calib, R)
    target = calib.target
    if zoom != 1.0:
        target = replace(target, fx_px=target.fx_px * zoom, fy_px=target.fy_px * zoom)
    cams = []
    for model, T in ((calib.left, Tl), (calib.right, Tr)):
        T_rect = np.eye(4)
        T_rect[:3, :3], T_rect[:3, 3] = R, T[:3, 3]
        cams.append(replace(target, name=model.name, T_rover_cam=T_rect))
    return StereoRig(cams[0], cams[1])


def rectify_table(model: CameraModel, rect: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """(map_u, map_v) float32 of shape (rect.height_px, rect.width_px): raw pixel seen by each rectified pixel."""
    u, v = np.meshgrid(np.arange(rect.width_px, dtype=float), np.arange(rect.height_px, dtype=float))
    rays = np.stack([(u.ravel() - rect.cx_px) / rect.fx_px, (v.ravel() - rect.cy_px) / rect.fy_px,
                     np.ones(u.size)], axis=1)  # fmt: skip
    R_raw_rect = model.T_rover_cam[:3, :3].T @ rect.T_rover_cam[:3, :3]
    uv = model.project(rays @ R_raw_rect.T)
    uv = np.where(np.isfinite(uv), uv, -1e4)
    shape = (rect.height_px, rect.width_px)
    return uv[:, 0].reshape(shape).astype(np.float32), uv[:, 1].reshape(shape).astype(np.float32)


_CACHE: dict[str, Rectification] = {}


def rectification(calib: StereoCalibration) -> Rectification:
    """Rig and tables for ``calib``, computed once per calibration (least recently built dropped first)."""
    key = calib.key()
    hit = _CACHE.get(key)
    if hit is not None:
        return hit
    rig = rectified_rig(calib)
    out = Rectification(rig, rectify_table(calib.left, rig.left), rectify_table(calib.right, rig.right))
    if len(_CACHE) >= CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = out
    return out


def epipolar_row_error_px(
    rect: Rectification,
    calib: StereoCalibration,
    true_left: CameraModel,
    true_right: CameraModel,
    uv_left: np.ndarray,
    disparity_px: np.ndarray,
) -> np.ndarray:
    """Row disparity (right minus left, rectified px) that ``rect`` (built from ``calib``) leaves for the scene
    points seen at rectified-left pixels ``uv_left`` (Nx2) with ``disparity_px`` (N), when the cameras truly are
    ``true_left`` / ``true_right``: the ground-truth epipolar error of a calibration, free of matching noise.

    Each point: rectified-left pixel -> raw pixel (the left table, through the calibrated model) -> the true
    model's ray of that raw pixel, at the depth the disparity gives in the rectified rig -> the true right
    camera's raw pixel -> the rectified-right pixel the calibrated right model assigns it. Zero for an exact
    calibration (``calib``'s models equal to the true ones) at any depth.
    """
    rig = rect.rig
    R = rig.left.T_rover_cam[:3, :3]
    uv = np.atleast_2d(np.asarray(uv_left, dtype=float))
    rays = np.stack([(uv[:, 0] - rig.left.cx_px) / rig.left.fx_px, (uv[:, 1] - rig.left.cy_px) / rig.left.fy_px,
                     np.ones(len(uv))], axis=1)  # fmt: skip
    raw_left = calib.left.project(rays @ (calib.left.T_rover_cam[:3, :3].T @ R).T)
    d = true_left.unproject(raw_left) @ true_left.T_rover_cam[:3, :3].T  # rover frame
    depth_m = rig.left.fx_px * rig.baseline_m / np.asarray(disparity_px, dtype=float)  # along the rectified axis
    p = true_left.T_rover_cam[:3, 3] + (depth_m / (d @ R[:, 2]))[:, None] * d
    raw_right = true_right.project((p - true_right.T_rover_cam[:3, 3]) @ true_right.T_rover_cam[:3, :3])
    ray = calib.right.unproject(raw_right) @ (R.T @ calib.right.T_rover_cam[:3, :3]).T
    return rig.right.fy_px * ray[:, 1] / ray[:, 2] + rig.right.cy_px - uv[:, 1]
