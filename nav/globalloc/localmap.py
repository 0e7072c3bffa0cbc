"""Step 1 of global localisation: the local orthomosaic and elevation of a navcam panorama, from stereo.

Every pair of the panorama is binned, matched with MER SAD stereo (:func:`nav.stereo.compute_disparity`) and
triangulated with *its* calibrated rig; the points (with the left image's grey level, normalised by the image's
median to undo exposure differences) go into a level frame centred on the rover through the onboard attitude
(IMU roll and pitch, the prior's yaw). The local map is then gridded per yaw hypothesis: mean grey level per
orthoimage pixel (the orthomosaic) and mean height per DEM post (the local elevation).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from nav.camera import StereoRig
from nav.globalloc.params import GlobalLocParams
from nav.stereo import compute_disparity, disparity_to_xyz_cam, xyz_cam_to_rover

ROVER_BOX_HALF_M = (1.2, 1.45)  # the rover's own body, wings and wheels (rover frame |x|, |y|): dropped


@dataclass(frozen=True)
class PanoramaView:
    """One rectified navcam pair of the panorama and its calibrated rig (rover frame, at the mast's pointing)."""

    left_u8: np.ndarray
    right_u8: np.ndarray
    rig: StereoRig


@dataclass(frozen=True)
class LocalPoints:
    """Panorama points in the level frame centred on the rover (x east, y north under the prior's yaw, z up)."""

    xyz_m: np.ndarray  # (N, 3)
    grey: np.ndarray  # (N,) normalised grey level (image median = 1)


def panorama_points(views: list[PanoramaView], R_world_rover: np.ndarray, p: GlobalLocParams) -> LocalPoints:
    """Stereo points of all views, rotated into the level frame by the onboard attitude (see module docstring)."""
    xyz_all, grey_all = [], []
    for v in views:
        k = max(1, int(p.binning))
        h, w = v.left_u8.shape
        left = cv2.resize(v.left_u8, (w // k, h // k), interpolation=cv2.INTER_AREA) if k > 1 else v.left_u8
        right = cv2.resize(v.right_u8, (w // k, h // k), interpolation=cv2.INTER_AREA) if k > 1 else v.right_u8
        rig = v.rig.scaled(1.0 / k) if k > 1 else v.rig
        d = compute_disparity(left, right, p.stereo)
        xyz = xyz_cam_to_rover(disparity_to_xyz_cam(d, rig), rig.left)
        ok = np.isfinite(xyz[..., 2])
        pts, g = xyz[ok], left[ok].astype(np.float64)
        body = (np.abs(pts[:, 0]) < ROVER_BOX_HALF_M[0]) & (np.abs(pts[:, 1]) < ROVER_BOX_HALF_M[1])
        pts, g = pts[~body], g[~body]
        med = float(np.median(g)) if len(g) else 1.0
        xyz_all.append(pts @ np.asarray(R_world_rover, float).T)
        grey_all.append(g / max(med, 1.0))
    if not xyz_all:
        return LocalPoints(np.zeros((0, 3)), np.zeros(0))
    xyz, grey = np.concatenate(xyz_all), np.concatenate(grey_all)
    rng = np.hypot(xyz[:, 0], xyz[:, 1])
    keep = (rng >= p.min_range_m) & (rng <= p.max_range_m)
    return LocalPoints(xyz[keep], grey[keep])


@dataclass(frozen=True)
class LocalGrid:
    """A gridded local map: ``values[r, c]`` at ``(x0 + c px, y0 + r px)`` relative to the rover; NaN: unseen."""

    values: np.ndarray
    counts: np.ndarray
    x0_m: float
    y0_m: float
    px_m: float


def grid_points(xy_m: np.ndarray, values: np.ndarray, px_m: float, half_m: float) -> LocalGrid:
    """Mean of ``values`` per cell of a square grid of side ``2 half_m`` centred on the rover (cell centres on a
    lattice through the rover's position)."""
    n = int(np.ceil(half_m / px_m))
    size = 2 * n + 1
    ij = np.rint(xy_m / px_m).astype(np.int64) + n
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < size) & (ij[:, 1] >= 0) & (ij[:, 1] < size)
    flat = ij[ok, 1] * size + ij[ok, 0]
    counts = np.bincount(flat, minlength=size * size).reshape(size, size)
    sums = np.bincount(flat, weights=values[ok], minlength=size * size).reshape(size, size)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    return LocalGrid(mean, counts, -n * px_m, -n * px_m, px_m)


def rotate_xy(xyz_m: np.ndarray, yaw_rad: float) -> np.ndarray:
    """Horizontal coordinates turned by ``yaw_rad`` about the vertical."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    x, y = xyz_m[:, 0], xyz_m[:, 1]
    return np.c_[c * x - s * y, s * x + c * y]


def highpass(values: np.ndarray, valid: np.ndarray, sigma_px: float) -> np.ndarray:
    """``values`` minus their local mean (normalised Gaussian over valid cells); 0 where invalid."""
    v = np.where(valid, values, 0.0).astype(np.float64)
    wsum = cv2.GaussianBlur(valid.astype(np.float64), (0, 0), sigma_px)
    vsum = cv2.GaussianBlur(v, (0, 0), sigma_px)
    with np.errstate(invalid="ignore", divide="ignore"):
        local = np.where(wsum > 1e-6, vsum / np.maximum(wsum, 1e-6), 0.0)
    return np.where(valid, v - local, 0.0)
