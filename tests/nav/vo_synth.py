"""Test fixture: a tiny pure-numpy ray caster rendering rectified stereo pairs of a textured heightfield.

Not production code. The ground is a heightfield with gentle bumps, its albedo seeded band-limited noise defined on a
1 cm world grid (so the texture is fixed to the ground as the camera moves). Lambertian shading under a sun, an
optional rover-fixed shadow polygon (the Sol 235 failure mode), supersampled 2x2 and binned like MER's 1024 -> 256
navcam images, Gaussian sensor noise, 8-bit quantisation.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from matplotlib.path import Path

from nav.camera import PinholeCamera, StereoRig
from nav.geometry import rpy_to_R, se3, se3_inv


@dataclass(frozen=True)
class SynthTerrain:
    origin_xy_m: np.ndarray  # world (x, y) of grid cell [0, 0] (row = y, column = x)
    res_m: float
    height_m: np.ndarray
    dh_dx: np.ndarray
    dh_dy: np.ndarray
    albedo: np.ndarray

    def sample(self, grid: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Bilinear interpolation (OpenCV remap, clamped at the border) of a float32 grid (R, C) or stack (R, C, K)
        at world points; OpenCV's 1/32-cell position quantisation is a fixed property of the ground, the same
        from every viewpoint."""
        n = np.size(x)
        w = 1024
        pad = (-n) % w  # OpenCV maps must stay below 32767 rows/columns
        mx = np.pad((np.ravel(x) - self.origin_xy_m[0]) / self.res_m, (0, pad)).astype(np.float32).reshape(-1, w)
        my = np.pad((np.ravel(y) - self.origin_xy_m[1]) / self.res_m, (0, pad)).astype(np.float32).reshape(-1, w)
        out = cv2.remap(grid, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out = out.reshape(mx.size, -1)[:n]
        return out[:, 0] if grid.ndim == 2 else out

    @property
    def height_and_slopes(self) -> np.ndarray:
        """(R, C, 3) float32 stack of height, dh/dx, dh/dy (cached)."""
        if "_hs" not in self.__dict__:
            hs = np.stack([self.height_m, self.dh_dx, self.dh_dy], axis=-1).astype(np.float32)
            object.__setattr__(self, "_hs", hs)
        return self.__dict__["_hs"]


def band_limited_noise(shape: tuple[int, int], res_m: float, wl_min_m: float, wl_max_m: float, rng) -> np.ndarray:
    """Zero-mean unit-std noise whose spatial wavelengths lie between wl_min_m and wl_max_m (smooth band edges)."""
    white = rng.standard_normal(shape)
    fy = np.fft.fftfreq(shape[0], d=res_m)[:, None]
    fx = np.fft.rfftfreq(shape[1], d=res_m)[None, :]
    f = np.hypot(fx, fy)
    lo, hi = 1.0 / wl_max_m, 1.0 / wl_min_m
    band = (1.0 / (1.0 + (lo / np.maximum(f, 1e-9)) ** 4)) * np.exp(-((f / hi) ** 2) * 2.0)
    out = np.fft.irfft2(np.fft.rfft2(white) * band, s=shape)
    return (out - out.mean()) / out.std()


def make_terrain(
    seed: int = 0,
    size_m: float = 8.0,
    res_m: float = 0.01,
    centre_xy_m: tuple[float, float] = (2.5, 0.0),
    texture_contrast: float = 0.22,
    bumps: bool = True,
) -> SynthTerrain:
    """Heightfield with a few smooth bumps (5-15 cm, slopes < 0.25) and band-limited albedo (0 contrast = uniform)."""
    rng = np.random.default_rng(seed)
    n = int(round(size_m / res_m))
    origin = np.array(centre_xy_m) - size_m / 2
    x = origin[0] + res_m * np.arange(n)
    y = origin[1] + res_m * np.arange(n)
    X, Y = np.meshgrid(x, y)
    H = np.zeros((n, n))
    if bumps:
        for _ in range(12):
            cx, cy = rng.uniform(origin[0], origin[0] + size_m), rng.uniform(origin[1], origin[1] + size_m)
            amp, sig = rng.uniform(-0.15, 0.15), rng.uniform(0.3, 0.6)
            H += amp * np.exp(-((X - cx) ** 2 + (Y - cy) ** 2) / (2 * sig**2))
    dy, dx = np.gradient(H, res_m)
    tex = band_limited_noise((n, n), res_m, 0.06, 0.5, rng)
    albedo = np.clip(0.5 + texture_contrast * 0.45 * tex, 0.05, 0.95)
    f32 = np.float32
    return SynthTerrain(origin, res_m, H.astype(f32), dx.astype(f32), dy.astype(f32), albedo.astype(f32))


def make_rig(
    height_above_ground_m: float = 1.0,
    pitch_down_deg: float = 40.0,
    fov_deg: float = 45.0,
    size_px: int = 256,
    baseline_m: float = 0.2,
    body_height_m: float = 0.5,
    x_forward_m: float = 0.3,
) -> StereoRig:
    """A rectified navcam-like pair on the rover: optical axis pitched down, right camera along camera +x."""
    th = np.radians(pitch_down_deg)
    z_c = np.array([np.cos(th), 0.0, -np.sin(th)])  # optical axis in the rover frame
    x_c = np.array([0.0, -1.0, 0.0])  # image right = rover -y
    y_c = np.cross(z_c, x_c)  # image down
    R = np.stack([x_c, y_c, z_c], axis=1)
    t_left = np.array([x_forward_m, baseline_m / 2, height_above_ground_m - body_height_m])
    left = PinholeCamera.from_fov("navcam_left", size_px, size_px, fov_deg, se3(R, t_left))
    right = PinholeCamera.from_fov("navcam_right", size_px, size_px, fov_deg, se3(R, t_left + baseline_m * x_c))
    return StereoRig(left, right)


def rover_pose(terrain: SynthTerrain, x: float, y: float, yaw_deg: float, roll_deg=0.0, pitch_deg=0.0, body=0.5):
    """World pose (4x4) of a rover standing at (x, y) with its body ``body`` m above the local ground."""
    z = float(terrain.sample(terrain.height_m, np.array([x]), np.array([y]))[0]) + body
    return se3(rpy_to_R(np.radians(roll_deg), np.radians(pitch_deg), np.radians(yaw_deg)), np.array([x, y, z]))


def raycast(terrain: SynthTerrain, origin: np.ndarray, dirs: np.ndarray, iterations: int = 6) -> np.ndarray:
    """Intersection of rays with the heightfield (Newton on ``z(t) - h(x(t), y(t))``, starting at the z=0 plane)."""
    t = -origin[2] / np.minimum(dirs[:, 2], -1e-3)
    hs = terrain.height_and_slopes
    for _ in range(iterations):
        p = origin + t[:, None] * dirs
        h, hx, hy = terrain.sample(hs, p[:, 0], p[:, 1]).astype(float).T
        f = p[:, 2] - h
        fp = dirs[:, 2] - hx * dirs[:, 0] - hy * dirs[:, 1]
        t = t - f / np.minimum(fp, -1e-3)
    return origin + t[:, None] * dirs


def render_view(
    terrain: SynthTerrain,
    cam: PinholeCamera,
    T_world_rover: np.ndarray,
    rng: np.random.Generator,
    supersample: int = 2,
    sun_dir_world=(-0.5, 0.3, 0.8),
    ambient: float = 0.35,
    shadow_polygon_rover: np.ndarray | None = None,
    noise_grey: float = 0.7,
) -> np.ndarray:
    """Render one 8-bit image of the terrain seen by ``cam`` mounted on a rover at ``T_world_rover``."""
    hi = cam.scaled(supersample)
    u, v = np.meshgrid(np.arange(hi.width_px), np.arange(hi.height_px))
    rays = hi.ray(np.stack([u.ravel(), v.ravel()], axis=1))
    T_wc = T_world_rover @ cam.T_rover_cam
    P = raycast(terrain, T_wc[:3, 3], rays @ T_wc[:3, :3].T)
    alb = terrain.sample(terrain.albedo, P[:, 0], P[:, 1])
    _, hx, hy = terrain.sample(terrain.height_and_slopes, P[:, 0], P[:, 1]).astype(float).T
    nrm = np.stack([-hx, -hy, np.ones_like(hx)], axis=1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    sun = np.asarray(sun_dir_world, dtype=float)
    direct = np.clip(nrm @ (sun / np.linalg.norm(sun)), 0.0, 1.0)
    if shadow_polygon_rover is not None:
        p_r = P @ se3_inv(T_world_rover)[:3, :3].T + se3_inv(T_world_rover)[:3, 3]
        direct = np.where(Path(shadow_polygon_rover).contains_points(p_r[:, :2]), 0.0, direct)
    img = 255.0 * alb * (ambient + (1.0 - ambient) * direct) / 0.8
    s = supersample
    img = img.reshape(cam.height_px, s, cam.width_px, s).mean(axis=(1, 3))
    img = img + noise_grey * rng.standard_normal(img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def render_pair(terrain: SynthTerrain, rig: StereoRig, T_world_rover: np.ndarray, seed: int = 0, **kw):
    rng = np.random.default_rng(seed)
    return render_view(terrain, rig.left, T_world_rover, rng, **kw), render_view(
        terrain, rig.right, T_world_rover, rng, **kw
    )


# A rover-fixed shadow on the ground ahead of a rover with the sun behind it: body with solar-panel notches, a mast
# and a camera head (rover-frame x, y in metres).
ROVER_SHADOW_POLYGON = np.array(
    [
        [1.05, -0.75], [1.25, -0.75], [1.25, -0.55], [1.55, -0.55], [1.55, -0.80], [1.85, -0.80],
        [1.85, -0.10], [2.60, -0.10], [2.60, -0.28], [2.85, -0.28], [2.85, 0.22], [2.60, 0.22],
        [2.60, 0.05], [1.85, 0.05], [1.85, 0.80], [1.55, 0.80], [1.55, 0.55], [1.25, 0.55],
        [1.25, 0.75], [1.05, 0.75],
    ]
)  # fmt: skip


def motion_error(M_est: np.ndarray, M_ref: np.ndarray) -> tuple[float, float]:
    """(translation error m, rotation error deg) between two 4x4 motions."""
    E = se3_inv(M_ref) @ M_est
    ang = np.degrees(np.arccos(np.clip((np.trace(E[:3, :3]) - 1) / 2, -1.0, 1.0)))
    return float(np.linalg.norm(M_est[:3, 3] - M_ref[:3, 3])), float(ang)
