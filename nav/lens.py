"""Camera models as flown: CAHVOR (navcams) and a Kannala-Brandt equidistant fisheye (hazcams).

JPL calibrated the MER cameras with the CAHV family (Yakimovsky & Cunningham 1978; Gennery 2006): CAHVOR for the
45 deg navcams (a pinhole ``CAHV`` plus radial distortion about an optical axis ``O`` with coefficients
``R = (r0, r1, r2)``) and CAHVORE for the 124 deg f-theta hazcams (Maki et al. 2003, "Mars Exploration Rover
engineering cameras", JGR 108(E12) 8071).

Both models here use the conventions of :mod:`nav.camera` (camera frame x right, y down, z forward; pixel (0, 0)
is the centre of the top-left pixel; ``T_rover_cam`` maps camera-frame points to the rover frame), so they convert
to and from :class:`~nav.camera.PinholeCamera` by dropping / adding the distortion terms.

* :class:`CahvorCamera`: CAHVOR written in the camera frame. With ``p`` a camera-frame point, ``o`` the unit
  distortion axis, ``zeta = p.o``, ``lam = p - zeta o``, ``tau = |lam|^2 / zeta^2`` and
  ``mu = r0 + r1 tau + r2 tau^2``, the point is moved to ``p' = p + mu lam`` and projected by the pinhole
  (``H``, ``V`` of CAHV are ``fx h + cx a`` and ``fy v + cy a``). :meth:`CahvorCamera.cahvor_vectors` gives the
  flight parameterisation (C, A, H, V, O, R in the rover frame).
* :class:`FisheyeCamera`: the hazcam model. **Kannala-Brandt** (Kannala & Brandt 2006, TPAMI 28(8)), not CAHVORE:
  the MER hazcams are f-theta lenses (Maki 2003: 2.1 mrad/px at the centre, 124 deg over 1024 px, i.e. within a
  few per cent of ``r = f theta``), which KB represents exactly with ``k = 0`` and corrects with an odd polynomial
  in ``theta``; it stays valid past 90 deg off axis, has closed-form Jacobians, and is the model of OpenCV's
  ``cv2.fisheye`` (so tests cross-check against an independent implementation). CAHVORE's extra term, the entrance
  pupil moving along the axis with the field angle, shifts rays by under a millimetre for these lenses, which is
  below a pixel beyond 0.3 m; we leave it out (the hazcams see the ground from 0.5 m on).
  ``theta = atan2(|xy|, z)``, ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``,
  ``u = fx theta_d x / |xy| + cx``, ``v = fy theta_d y / |xy| + cy``.

Every model gives ``project`` (Nx3 camera-frame points -> Nx2 pixels), ``unproject`` (pixels -> unit rays) and
``jacobian`` (N x 2 x 3, d pixel / d point).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from nav.camera import PinholeCamera

NEWTON_ITERATIONS = 20  # scalar Newton steps of the unprojections (converge in < 6 from the undistorted guess)


class CameraModel(Protocol):
    """What rectification and rendering need from a camera model."""

    name: str
    width_px: int
    height_px: int
    T_rover_cam: np.ndarray

    def project(self, points_cam: np.ndarray) -> np.ndarray: ...
    def unproject(self, uv: np.ndarray) -> np.ndarray: ...
    def scaled(self, factor: float) -> CameraModel: ...
    def pinhole(self) -> PinholeCamera: ...


def _pinhole_jacobian(p: np.ndarray, fx: float, fy: float) -> np.ndarray:
    """(N, 2, 3) d(u, v)/d(x, y, z) of the pinhole ``u = fx x / z + cx``."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    J = np.zeros((len(p), 2, 3))
    J[:, 0, 0] = fx / z
    J[:, 0, 2] = -fx * x / z**2
    J[:, 1, 1] = fy / z
    J[:, 1, 2] = -fy * y / z**2
    return J


def _scaled_intrinsics(cam, factor: float) -> dict:  # noqa: ANN001 - any model with the five intrinsic fields
    """Intrinsics after binning/resampling by ``factor`` (``u' = (u + 0.5) factor - 0.5``, as PinholeCamera)."""
    return dict(
        width_px=int(round(cam.width_px * factor)),
        height_px=int(round(cam.height_px * factor)),
        fx_px=cam.fx_px * factor,
        fy_px=cam.fy_px * factor,
        cx_px=(cam.cx_px + 0.5) * factor - 0.5,
        cy_px=(cam.cy_px + 0.5) * factor - 0.5,
    )


@dataclass(frozen=True)
class CahvorCamera:
    """CAHVOR in the camera frame (see the module docstring); ``o_cam`` is the distortion axis (unit)."""

    name: str
    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    r: tuple[float, float, float] = (0.0, 0.0, 0.0)
    o_cam: tuple[float, float, float] = (0.0, 0.0, 1.0)
    T_rover_cam: np.ndarray = field(default_factory=lambda: np.eye(4))

    # -- conversions
    @staticmethod
    def from_pinhole(cam: PinholeCamera, r: tuple[float, float, float] = (0.0, 0.0, 0.0),
                     o_cam: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> CahvorCamera:  # fmt: skip
        """The pinhole's CAHV plus distortion ``r`` about ``o_cam`` (default: the optical axis)."""
        o = np.asarray(o_cam, dtype=float)
        return CahvorCamera(cam.name, cam.width_px, cam.height_px, cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px,
                            tuple(float(x) for x in r), tuple(float(x) for x in o / np.linalg.norm(o)),
                            np.asarray(cam.T_rover_cam, dtype=float))  # fmt: skip

    def pinhole(self) -> PinholeCamera:
        """The CAHV part (distortion dropped)."""
        return PinholeCamera(self.name, self.width_px, self.height_px, self.fx_px, self.fy_px, self.cx_px,
                             self.cy_px, self.T_rover_cam)  # fmt: skip

    def scaled(self, factor: float) -> CahvorCamera:
        return replace(self, **_scaled_intrinsics(self, factor))

    def cahvor_vectors(self) -> dict[str, np.ndarray]:
        """C, A, H, V, O (rover frame) and R: the flight CAHVOR parameterisation of this model."""
        R, C = self.T_rover_cam[:3, :3], self.T_rover_cam[:3, 3]
        a, h, v = R[:, 2], R[:, 0], R[:, 1]
        return {"C": C.copy(), "A": a, "H": self.fx_px * h + self.cx_px * a, "V": self.fy_px * v + self.cy_px * a,
                "O": R @ np.asarray(self.o_cam), "R": np.asarray(self.r, dtype=float)}  # fmt: skip

    # -- geometry
    def _distort(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        o = np.asarray(self.o_cam)
        zeta = p @ o
        lam = p - zeta[:, None] * o
        tau = np.einsum("ij,ij->i", lam, lam) / zeta**2
        r0, r1, r2 = self.r
        mu = r0 + r1 * tau + r2 * tau**2
        return p + mu[:, None] * lam, zeta, lam, tau, mu

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Nx3 camera-frame points -> Nx2 pixels; NaN behind the camera."""
        p = np.atleast_2d(np.asarray(points_cam, dtype=float))
        with np.errstate(divide="ignore", invalid="ignore"):
            q = self._distort(p)[0]
            uv = np.stack([self.fx_px * q[:, 0] / q[:, 2] + self.cx_px, self.fy_px * q[:, 1] / q[:, 2] + self.cy_px], 1)
        uv[(p @ np.asarray(self.o_cam) <= 0) | (q[:, 2] <= 0)] = np.nan
        return uv

    def jacobian(self, points_cam: np.ndarray) -> np.ndarray:
        """(N, 2, 3) d pixel / d camera-frame point."""
        p = np.atleast_2d(np.asarray(points_cam, dtype=float))
        o = np.asarray(self.o_cam)
        q, zeta, lam, tau, mu = self._distort(p)
        _, r1, r2 = self.r
        dtau = 2.0 * lam / zeta[:, None] ** 2 - 2.0 * (tau / zeta)[:, None] * o  # (N, 3)
        dmu = (r1 + 2.0 * r2 * tau)[:, None] * dtau
        P = np.eye(3) - np.outer(o, o)
        dq = np.eye(3) + mu[:, None, None] * P + lam[:, :, None] * dmu[:, None, :]
        return _pinhole_jacobian(q, self.fx_px, self.fy_px) @ dq

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Unit camera-frame rays through pixels ``uv`` (Nx2): the pinhole ray of ``p'``, undistorted exactly.

        ``p'`` and ``p`` share ``zeta`` and the direction of ``lam``; only ``s = |lam| / zeta`` changes, as
        ``s' = s (1 + r0 + r1 s^2 + r2 s^4)``, which is solved for ``s`` by Newton's method.
        """
        q = self.pinhole().ray(uv)
        o = np.asarray(self.o_cam)
        zeta = q @ o
        lam_q = q - zeta[:, None] * o
        s_q = np.linalg.norm(lam_q, axis=1) / zeta
        r0, r1, r2 = self.r
        s = s_q / (1.0 + r0)
        for _ in range(NEWTON_ITERATIONS):
            f = s * (1.0 + r0 + r1 * s**2 + r2 * s**4) - s_q
            s = s - f / (1.0 + r0 + 3.0 * r1 * s**2 + 5.0 * r2 * s**4)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(s_q > 0, s / s_q, 1.0 / (1.0 + r0))
        d = zeta[:, None] * o + scale[:, None] * lam_q
        return d / np.linalg.norm(d, axis=1, keepdims=True)


@dataclass(frozen=True)
class FisheyeCamera:
    """Kannala-Brandt equidistant fisheye (OpenCV ``cv2.fisheye`` model; see the module docstring)."""

    name: str
    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    k: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    T_rover_cam: np.ndarray = field(default_factory=lambda: np.eye(4))

    @staticmethod
    def from_fov(name: str, width_px: int, height_px: int, hfov_deg: float,
                 k: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
                 T_rover_cam: np.ndarray | None = None) -> FisheyeCamera:  # fmt: skip
        """Square-pixel fisheye whose image width spans ``hfov_deg`` (edge to edge), principal point centred."""
        half = np.radians(hfov_deg) / 2.0
        k1, k2, k3, k4 = k
        theta_d = half * (1 + k1 * half**2 + k2 * half**4 + k3 * half**6 + k4 * half**8)
        f = 0.5 * width_px / theta_d
        return FisheyeCamera(name, width_px, height_px, float(f), float(f), (width_px - 1) / 2.0,
                             (height_px - 1) / 2.0, tuple(float(x) for x in k),
                             np.eye(4) if T_rover_cam is None else np.asarray(T_rover_cam, dtype=float))  # fmt: skip

    @staticmethod
    def from_pinhole(cam: PinholeCamera, k: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)) -> FisheyeCamera:
        """The fisheye with the pinhole's intrinsics read as equidistant ones (same centre magnification)."""
        return FisheyeCamera(cam.name, cam.width_px, cam.height_px, cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px,
                             tuple(float(x) for x in k), np.asarray(cam.T_rover_cam, dtype=float))  # fmt: skip

    def pinhole(self) -> PinholeCamera:
        """The pinhole with the same centre magnification and principal point (matches the fisheye near axis)."""
        return PinholeCamera(self.name, self.width_px, self.height_px, self.fx_px, self.fy_px, self.cx_px,
                             self.cy_px, self.T_rover_cam)  # fmt: skip

    def scaled(self, factor: float) -> FisheyeCamera:
        return replace(self, **_scaled_intrinsics(self, factor))

    def _theta_d(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """theta_d(theta) and its derivative."""
        k1, k2, k3, k4 = self.k
        t2 = theta**2
        td = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
        dtd = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
        return td, dtd

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Nx3 camera-frame points -> Nx2 pixels (valid up to the polynomial's monotonic range)."""
        p = np.atleast_2d(np.asarray(points_cam, dtype=float))
        rho = np.hypot(p[:, 0], p[:, 1])
        theta = np.arctan2(rho, p[:, 2])
        td, _ = self._theta_d(theta)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(rho > 1e-12, td / rho, 1.0 / np.where(p[:, 2] > 0, p[:, 2], np.nan))
        return np.stack([self.fx_px * g * p[:, 0] + self.cx_px, self.fy_px * g * p[:, 1] + self.cy_px], axis=1)

    def jacobian(self, points_cam: np.ndarray) -> np.ndarray:
        """(N, 2, 3) d pixel / d camera-frame point (points off the optical axis)."""
        p = np.atleast_2d(np.asarray(points_cam, dtype=float))
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        rho2 = x**2 + y**2
        rho = np.sqrt(rho2)
        n2 = rho2 + z**2
        theta = np.arctan2(rho, z)
        td, dtd = self._theta_d(theta)
        g = td / rho  # u = fx g x + cx
        dtheta = np.stack([x * z / (rho * n2), y * z / (rho * n2), -rho / n2], axis=1)  # d theta / d p
        drho = np.stack([x / rho, y / rho, np.zeros_like(x)], axis=1)
        dg = (dtd / rho)[:, None] * dtheta - (td / rho2)[:, None] * drho
        J = np.zeros((len(p), 2, 3))
        J[:, 0] = self.fx_px * (x[:, None] * dg)
        J[:, 1] = self.fy_px * (y[:, None] * dg)
        J[:, 0, 0] += self.fx_px * g
        J[:, 1, 1] += self.fy_px * g
        return J

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Unit camera-frame rays through pixels ``uv`` (Nx2); ``theta_d -> theta`` by Newton's method."""
        uv = np.atleast_2d(np.asarray(uv, dtype=float))
        mx = (uv[:, 0] - self.cx_px) / self.fx_px
        my = (uv[:, 1] - self.cy_px) / self.fy_px
        td = np.hypot(mx, my)
        theta = td.copy()
        for _ in range(NEWTON_ITERATIONS):
            f, df = self._theta_d(theta)
            theta = theta - (f - td) / df
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(td > 1e-12, np.sin(theta) / td, 1.0)
        d = np.stack([mx * s, my * s, np.cos(theta)], axis=1)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def off_axis_deg(self, uv: np.ndarray) -> np.ndarray:
        """Angle (deg) between the optical axis and the ray of each pixel."""
        return np.degrees(np.arccos(np.clip(self.unproject(uv)[:, 2], -1.0, 1.0)))


def pixel_grid(width_px: int, height_px: int) -> np.ndarray:
    """(H*W, 2) pixel centres (u, v), row-major."""
    u, v = np.meshgrid(np.arange(width_px, dtype=float), np.arange(height_px, dtype=float))
    return np.stack([u.ravel(), v.ravel()], axis=1)
