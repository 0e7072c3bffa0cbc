"""Camera models consumed by the navigation stack.

Conventions (used everywhere in ``nav`` and by ``rover_sim`` when it exports cameras):

* **Camera frame** (OpenCV / CAHV-like): x right, y down, z forward along the optical axis, metres.
* **Rover frame**: x forward, y left, z up, origin at the rover body reference point (MuJoCo ``rover`` body frame).
* **World frame**: x east, y north, z up, metres.
* ``T_rover_cam`` is a 4x4 homogeneous transform that maps camera-frame points into the rover frame:
  ``p_rover = T_rover_cam @ [p_cam, 1]``.
* Pixels: ``u`` is the column, ``v`` the row, the centre of the top-left pixel is (0, 0).
* A :class:`StereoRig` is *rectified*: both cameras share intrinsics and orientation, the right camera sits
  ``baseline_m`` along the left camera's +x axis, so a point at depth ``Z`` has disparity ``d = fx * B / Z``
  with ``u_right = u_left - d``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np


@dataclass(frozen=True)
class PinholeCamera:
    """An ideal pinhole camera with its mounting pose on the rover."""

    name: str
    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    T_rover_cam: np.ndarray = field(default_factory=lambda: np.eye(4))

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix."""
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    @property
    def hfov_deg(self) -> float:
        return float(np.degrees(2.0 * np.arctan(0.5 * self.width_px / self.fx_px)))

    @staticmethod
    def from_fov(
        name: str, width_px: int, height_px: int, vfov_deg: float, T_rover_cam: np.ndarray | None = None
    ) -> PinholeCamera:
        """Square-pixel camera whose vertical field of view is ``vfov_deg`` (MuJoCo's ``fovy`` convention)."""
        f = 0.5 * height_px / np.tan(np.radians(vfov_deg) / 2.0)
        return PinholeCamera(
            name=name,
            width_px=width_px,
            height_px=height_px,
            fx_px=float(f),
            fy_px=float(f),
            cx_px=(width_px - 1) / 2.0,
            cy_px=(height_px - 1) / 2.0,
            T_rover_cam=np.eye(4) if T_rover_cam is None else np.asarray(T_rover_cam, dtype=float),
        )

    def scaled(self, factor: float) -> PinholeCamera:
        """The same camera after binning/resampling the image by ``factor`` (e.g. 0.25 for 1024 -> 256).

        Pixel centres map as ``u' = (u + 0.5) * factor - 0.5``.
        """
        return replace(
            self,
            width_px=int(round(self.width_px * factor)),
            height_px=int(round(self.height_px * factor)),
            fx_px=self.fx_px * factor,
            fy_px=self.fy_px * factor,
            cx_px=(self.cx_px + 0.5) * factor - 0.5,
            cy_px=(self.cy_px + 0.5) * factor - 0.5,
        )

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Project Nx3 camera-frame points to Nx2 pixels (u, v). Points behind the camera give NaN."""
        p = np.atleast_2d(np.asarray(points_cam, dtype=float))
        z = p[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.fx_px * p[:, 0] / z + self.cx_px
            v = self.fy_px * p[:, 1] / z + self.cy_px
        uv = np.stack([u, v], axis=1)
        uv[z <= 0] = np.nan
        return uv

    def ray(self, uv: np.ndarray) -> np.ndarray:
        """Unit viewing rays (camera frame, Nx3) through pixels ``uv`` (Nx2)."""
        uv = np.atleast_2d(np.asarray(uv, dtype=float))
        d = np.stack(
            [(uv[:, 0] - self.cx_px) / self.fx_px, (uv[:, 1] - self.cy_px) / self.fy_px, np.ones(len(uv))], axis=1
        )
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "width_px": self.width_px,
            "height_px": self.height_px,
            "fx_px": self.fx_px,
            "fy_px": self.fy_px,
            "cx_px": self.cx_px,
            "cy_px": self.cy_px,
            "T_rover_cam": np.asarray(self.T_rover_cam).tolist(),
        }

    @staticmethod
    def from_dict(d: dict) -> PinholeCamera:
        return PinholeCamera(**{**d, "T_rover_cam": np.asarray(d["T_rover_cam"], dtype=float)})


@dataclass(frozen=True)
class StereoRig:
    """A rectified stereo pair (see module docstring for conventions)."""

    left: PinholeCamera
    right: PinholeCamera

    @property
    def baseline_m(self) -> float:
        t = np.linalg.inv(self.left.T_rover_cam) @ self.right.T_rover_cam
        return float(np.linalg.norm(t[:3, 3]))

    @property
    def name(self) -> str:
        return self.left.name.removesuffix("_left")

    def disparity_from_depth(self, depth_m: np.ndarray) -> np.ndarray:
        """Disparity (px) of points at camera-frame depth ``Z`` (m)."""
        with np.errstate(divide="ignore"):
            return self.left.fx_px * self.baseline_m / np.asarray(depth_m, dtype=float)

    def depth_from_disparity(self, disparity_px: np.ndarray) -> np.ndarray:
        """Camera-frame depth ``Z`` (m) from disparity; NaN where disparity is not positive."""
        d = np.asarray(disparity_px, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = self.left.fx_px * self.baseline_m / d
        return np.where(d > 0, z, np.nan)

    def scaled(self, factor: float) -> StereoRig:
        return StereoRig(self.left.scaled(factor), self.right.scaled(factor))

    def to_dict(self) -> dict:
        return {"left": self.left.to_dict(), "right": self.right.to_dict(), "baseline_m": self.baseline_m}

    @staticmethod
    def from_dict(d: dict) -> StereoRig:
        return StereoRig(PinholeCamera.from_dict(d["left"]), PinholeCamera.from_dict(d["right"]))


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 homogeneous transform to Nx3 points."""
    p = np.atleast_2d(np.asarray(points, dtype=float))
    return p @ T[:3, :3].T + T[:3, 3]
