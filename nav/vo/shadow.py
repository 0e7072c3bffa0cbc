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


@dataclass(frozen=True)
class ShadowPrediction:
    """Per pixel (H, W) bool: the rover's shadow on the ground, and the rover itself in view."""

    shadow: np.ndarray
    hardware: np.ndarray


def _box_corners(boxes: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(N, 8, 3) corners of the oriented boxes."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    local = signs[None] * half[:, None, :]
    return np.einsum("nij,nkj->nki", boxes[:, :3, :3], local) + boxes[:, None, :3, 3]


def _fill_polygons(polys_rover: list[np.ndarray], cam: PinholeCamera, out: np.ndarray) -> None:
    """Fill the convex hulls of the projections of rover-frame point sets (each wholly in front of the camera)."""
    T = np.linalg.inv(cam.T_rover_cam)
    for P in polys_rover:
        Pc = P @ T[:3, :3].T + T[:3, 3]
        if np.any(Pc[:, 2] < NEAR_M):  # a vertex behind the camera: clip by sampling the segment ends in front
            continue
        uv = cam.project(Pc)
        hull = cv2.convexHull(np.round(uv * SUBPIXEL).astype(np.int32))
        cv2.fillConvexPoly(out, hull, 1, lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)


NEAR_M = 0.02
SUBPIXEL_BITS = 4
SUBPIXEL = 1 << SUBPIXEL_BITS


def predict_shadow(
    shape: RoverShape,
    cam: PinholeCamera,
    R_world_rover: np.ndarray,
    sun_direction_world: np.ndarray,
    T_rover_navcam: np.ndarray | None = None,
) -> ShadowPrediction:
    """Predict the rover's shadow in ``cam``'s image (see the module docstring).

    Each box's shadow on the ground plane is the convex hull of its eight corners cast along the sunlight; it and
    the box itself are projected into the image and filled (a convex ground polygon stays convex through a
    pinhole camera). Shadow polygons crossing behind the camera are skipped (the downward navcam never needs them).
    ``sun_direction_world``: the direction sunlight travels (from the sun toward the ground), unit, world frame;
    ``R_world_rover``: the onboard attitude; ``T_rover_navcam``: the calibrated navcam-left pose that places the
    mast head's boxes (None: the head is left out).
    """
    boxes, half = shape.posed(T_rover_navcam)
    s = np.asarray(R_world_rover, dtype=float).T @ np.asarray(sun_direction_world, dtype=float)
    s = s / np.linalg.norm(s)
    hw = (cam.height_px, cam.width_px)
    shadow, hardware = np.zeros(hw, np.uint8), np.zeros(hw, np.uint8)
    if len(boxes) == 0:
        return ShadowPrediction(shadow.astype(bool), hardware.astype(bool))
    corners = _box_corners(boxes, half)
    _fill_polygons(list(corners), cam, hardware)
    if s[2] < -1e-3:  # sun above the horizon
        t = (shape.ground_z_m - corners[..., 2]) / s[2]
        cast = corners + np.maximum(t, 0.0)[..., None] * s
        _fill_polygons(list(cast), cam, shadow)
    hardware_b = hardware.astype(bool)
    return ShadowPrediction(shadow.astype(bool) & ~hardware_b, hardware_b)


def vo_feature_mask(prediction: ShadowPrediction, margin_px: int = FEATURE_MARGIN_PX) -> np.ndarray:
    """``feature_mask`` for VO: False in the shadow and on the rover, widened by ``margin_px``; True elsewhere."""
    bad = (prediction.shadow | prediction.hardware).astype(np.uint8)
    if margin_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin_px + 1, 2 * margin_px + 1))
        bad = cv2.dilate(bad, k)
    return bad == 0
