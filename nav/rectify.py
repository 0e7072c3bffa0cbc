"""Onboard stereo rectification from the calibrated camera models (MER's "linearisation" before stereo).

MER flight software rectified each raw pair with its CAHVOR/CAHVORE models into a pair of aligned pinhole (CAHV)
models before stereo correlation and VO (Maki et al. 2003; Goldberg, Maimone & Matthies 2002, "Stereo vision and
rover navigation software for planetary exploration"). Here: from the calibrated left/right models build

* the rectified rig (:class:`~nav.camera.StereoRig`): both cameras keep their calibrated optical centres and take a
  common orientation whose x axis runs along the calibrated baseline and whose z axis is the mean of the two
  optical axes made orthogonal to it (Fusiello, Trucco & Verri 2000); intrinsics are the given ``target`` pinhole
  (the nominal camera at the output resolution, so an error-free calibration reproduces the ideal rig);
* remap tables (like ``cv2.initUndistortRectifyMap``, but through our models): for each rectified pixel, its ray
  in the rectified frame, rotated into the raw camera, projected by the calibrated model.

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


def rectified_rig(calib: StereoCalibration) -> StereoRig:
    """The rectified pinhole rig of ``calib`` (see the module docstring)."""
    Tl, Tr = calib.left.T_rover_cam, calib.right.T_rover_cam
    R = rectifying_rotation(Tl, Tr)
    cams = []
    for model, T in ((calib.left, Tl), (calib.right, Tr)):
        T_rect = np.eye(4)
        T_rect[:3, :3], T_rect[:3, 3] = R, T[:3, 3]
        cams.append(replace(calib.target, name=model.name, T_rover_cam=T_rect))
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
