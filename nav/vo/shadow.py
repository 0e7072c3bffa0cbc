"""Where the rover's own shadow falls in an image, predicted onboard (the Sol 235 false positive, seed 000 4.3).

On Sol 235 Spirit's VO followed the rover's shadow: its edges carried more corners than the fine soil and moved
with the rover. Flight software knew everything needed to predict it: the sun's direction (ephemeris from the
clock, turned into the rover frame with the IMU attitude), the vehicle's own shape (design data) and the
commanded camera pointing (the calibrated camera model). :func:`predict_shadow` casts the shape's shadow onto
the local ground plane and renders it into the camera: a pixel is shadowed when its viewing ray meets the ground
at a point from which the ray toward the sun hits one of the shape's boxes. :func:`vo_feature_mask` turns that
into the ``feature_mask`` of :meth:`nav.vo.VisualOdometry.step` (False in and near the shadow, and where the
camera sees the rover itself).

The shape is a list of oriented boxes (:class:`RoverShape`): the body's boxes in the rover frame, and the mast
head's boxes in the navcam-left camera frame (they move with the pointing, which the calibrated navcam model
gives). Pure numpy/OpenCV: nothing here reads the simulator.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from nav.camera import PinholeCamera

FEATURE_MARGIN_PX = 7  # a feature's correlation window (11 px) must not reach into the shadow: half-window + 2


def _empty_boxes() -> np.ndarray:
    return np.zeros((0, 4, 4))


@dataclass(frozen=True)
class RoverShape:
    """The vehicle as oriented boxes (design data, taken once at the home pose).

    ``boxes`` (N, 4, 4): each box's pose in the rover frame with its half-sizes in ``half_m`` (N, 3);
    ``head_boxes``/``head_half_m``: boxes riding on the mast head, posed in the navcam-left camera frame (OpenCV
    axes); ``ground_z_m``: the ground plane through the wheel contacts, as a rover-frame height (negative).
    """

    boxes: np.ndarray = field(default_factory=_empty_boxes)
    half_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    head_boxes: np.ndarray = field(default_factory=_empty_boxes)
    head_half_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    ground_z_m: float = -0.525

    def posed(self, T_rover_navcam: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """All boxes in the rover frame: the head's placed with ``T_rover_navcam`` (omitted when None)."""
        if T_rover_navcam is None or len(self.head_boxes) == 0:
            return self.boxes, self.half_m
        head = np.asarray(T_rover_navcam, dtype=float) @ self.head_boxes
        return np.concatenate([self.boxes, head]), np.concatenate([self.half_m, self.head_half_m])


def _pixel_rays_rover(cam: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre (3,) and unit viewing rays (H*W, 3) of every pixel centre, in the rover frame."""
    u, v = np.meshgrid(np.arange(cam.width_px, dtype=float), np.arange(cam.height_px, dtype=float))
    d_cam = np.stack([(u - cam.cx_px) / cam.fx_px, (v - cam.cy_px) / cam.fy_px, np.ones_like(u)], -1).reshape(-1, 3)
    R, t = cam.T_rover_cam[:3, :3], cam.T_rover_cam[:3, 3]
    d = d_cam @ R.T
    return t, d / np.linalg.norm(d, axis=1, keepdims=True)


def _ray_hits_boxes(origin: np.ndarray, direction: np.ndarray, boxes: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Per ray (origins (M, 3) or (3,), directions (M, 3)): the nearest positive distance to any box, inf if none."""
    best = np.full(len(direction), np.inf)
    for T, h in zip(boxes, half, strict=True):
        R, c = T[:3, :3], T[:3, 3]
        o = (origin - c) @ R  # into the box frame
        d = direction @ R
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (-h - o) / d, (h - o) / d
        lo = np.nanmax(np.minimum(t1, t2), axis=-1)
        hi = np.nanmin(np.maximum(t1, t2), axis=-1)
        hit = (hi >= np.maximum(lo, 0.0)) & np.isfinite(hi)
        best = np.where(hit, np.minimum(best, np.maximum(lo, 0.0)), best)
    return best


@dataclass(frozen=True)
class ShadowPrediction:
    """Per pixel (H, W) bool: the rover's shadow on the ground, and the rover itself in view."""

    shadow: np.ndarray
    hardware: np.ndarray


def predict_shadow(
    shape: RoverShape,
    cam: PinholeCamera,
    R_world_rover: np.ndarray,
    sun_direction_world: np.ndarray,
    T_rover_navcam: np.ndarray | None = None,
) -> ShadowPrediction:
    """Predict the rover's shadow in ``cam``'s image (see the module docstring).

    ``sun_direction_world``: the direction sunlight travels (from the sun toward the ground), unit, world frame;
    ``R_world_rover``: the onboard attitude; ``T_rover_navcam``: the calibrated navcam-left pose that places the
    mast head's boxes (None: the head is left out).
    """
    boxes, half = shape.posed(T_rover_navcam)
    s = np.asarray(R_world_rover, dtype=float).T @ np.asarray(sun_direction_world, dtype=float)
    s = s / np.linalg.norm(s)
    c, d = _pixel_rays_rover(cam)
    hw = (cam.height_px, cam.width_px)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = (shape.ground_z_m - c[2]) / d[:, 2]
    on_ground = np.isfinite(t_ground) & (t_ground > 0)
    t_box = _ray_hits_boxes(c, d, boxes, half)
    hardware = t_box < np.where(on_ground, t_ground, np.inf)
    shadow = np.zeros(len(d), bool)
    sel = np.flatnonzero(on_ground & ~hardware)
    if len(sel) and s[2] < 0:  # sun above the horizon
        g = c + d[sel] * t_ground[sel, None]
        toward_sun = np.broadcast_to(-s, g.shape)
        shadow[sel] = np.isfinite(_ray_hits_boxes(g + 1e-4 * toward_sun, toward_sun, boxes, half))
    return ShadowPrediction(shadow.reshape(hw), hardware.reshape(hw))


def vo_feature_mask(prediction: ShadowPrediction, margin_px: int = FEATURE_MARGIN_PX) -> np.ndarray:
    """``feature_mask`` for VO: False in the shadow and on the rover, widened by ``margin_px``; True elsewhere."""
    bad = (prediction.shadow | prediction.hardware).astype(np.uint8)
    if margin_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin_px + 1, 2 * margin_px + 1))
        bad = cv2.dilate(bad, k)
    return bad == 0
