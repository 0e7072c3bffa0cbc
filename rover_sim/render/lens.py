"""The true lenses: raw, distorted images from the ideal pinhole render (``[sensors.lens]``).

MuJoCo renders pinhole images only. For each camera the true raw model (:mod:`nav.lens`: CAHVOR navcams,
Kannala-Brandt f-theta hazcams, each turned by its true mounting rotation relative to the MJCF camera) is formed
by rendering a wider pinhole view from the same optical centre and remapping it (``cv2.remap``, bilinear) into
the raw model's pixels: each raw pixel's ray under the true model, rotated into the MuJoCo camera frame, projected
by the render pinhole. The render pinhole's ``fovy`` (set on the render model's camera only while the pair is
drawn) is the smallest square view containing every raw pixel's ray, its size gives the raw model's centre
magnification times ``render_oversample``.

Hazcams: a 124 deg f-theta lens has a ~175 deg diagonal, which no pinhole can show. Raw hazcam pixels more than
``hazcam_max_off_axis_deg`` (71 deg) off axis are therefore vignetted to 0 (the image corners); the pinhole render
then spans about 136 deg (143 deg on its diagonal) and is about 2.2x the output side (574 px for 256^2 images).
The onboard rectified view (the 124 deg pinhole of the ideal profile, corners 69.4 deg off axis) reads none of
the vignetted pixels.

:class:`IdentityLens` (ideal profile) leaves the render untouched: the images are the pinhole ones, byte for byte.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace

import cv2
import mujoco
import numpy as np

from nav.camera import PinholeCamera
from nav.lens import CahvorCamera, CameraModel, FisheyeCamera, pixel_grid
from rover_sim.render.cameras import STEREO_PAIRS

EDGE_MARGIN_PX = 2.0  # render pixels kept beyond the outermost raw ray (bilinear neighbours)


def pair_of(cam_name: str) -> str:
    return cam_name.removesuffix("_left").removesuffix("_right")


def nominal_model(
    pinhole: PinholeCamera, navcam_r: tuple[float, float, float], hazcam_k: tuple[float, float, float, float]
) -> CameraModel:
    """The lens design of ``pinhole``'s camera: CAHVOR for navcams (radial terms ``navcam_r``), f-theta
    Kannala-Brandt for hazcams (``hazcam_k``), with the MJCF field of view (navcam: the pinhole's focal length;
    hazcam: its width spans the MJCF ``fovy``). The terms are ``[sensors.lens]``'s."""
    if pinhole.name.startswith("navcam"):
        return CahvorCamera.from_pinhole(pinhole, r=navcam_r)
    return FisheyeCamera.from_fov(pinhole.name, pinhole.width_px, pinhole.height_px, pinhole.hfov_deg,
                                  k=hazcam_k, T_rover_cam=pinhole.T_rover_cam)  # fmt: skip


def with_rotation(model: CameraModel, R: np.ndarray) -> CameraModel:
    """``model`` with ``T_rover_cam`` = ``R`` (3x3) as a pure rotation (a mounting offset)."""
    T = np.eye(4)
    T[:3, :3] = R
    return replace(model, T_rover_cam=T)  # type: ignore[type-var]


@dataclass(frozen=True)
class RenderView:
    """How a pair's ideal view is rendered and remapped: pinhole ``fovy``, render side, remap tables per camera."""

    fovy_deg: float
    px: int
    maps: dict[str, tuple[np.ndarray, np.ndarray]]


def render_view(models: list[CameraModel], max_off_axis_deg: float | None, oversample: float) -> RenderView:
    """The render pinhole covering every valid raw pixel of ``models`` (whose ``T_rover_cam`` holds the mounting
    rotation relative to the MuJoCo camera) and the raw <- render remap tables."""
    rays, valid = {}, {}
    for m in models:
        uv = pixel_grid(m.width_px, m.height_px)
        ray = m.unproject(uv) @ m.T_rover_cam[:3, :3].T  # raw camera frame -> MuJoCo camera frame (OpenCV axes)
        ok = np.ones(len(uv), bool)
        if max_off_axis_deg is not None:
            ok = m.unproject(uv)[:, 2] >= math.cos(math.radians(max_off_axis_deg))
        rays[m.name], valid[m.name] = ray, ok
    half_tan = max(float(np.max(np.abs(r[valid[n], :2]) / r[valid[n], 2:3])) for n, r in rays.items())
    f_raw = max(float(m.fx_px) for m in models)
    px = int(math.ceil(2.0 * half_tan * f_raw * oversample))
    half_tan *= 1.0 + 2.0 * EDGE_MARGIN_PX / px
    px = int(math.ceil(2.0 * half_tan * f_raw * oversample))
    fovy = math.degrees(2.0 * math.atan(half_tan))
    pin = PinholeCamera.from_fov("render", px, px, fovy)
    maps = {}
    for m in models:
        uv = pin.project(rays[m.name])
        uv[~valid[m.name]] = -1e4  # vignetted: outside the render, remapped to 0
        shape = (m.height_px, m.width_px)
        maps[m.name] = (uv[:, 0].reshape(shape).astype(np.float32), uv[:, 1].reshape(shape).astype(np.float32))
    return RenderView(fovy, px, maps)


class IdentityLens:
    """Ideal profile: pinhole cameras, no remap."""

    max_render_px = 0

    @contextmanager
    def view(self, model: mujoco.MjModel, pair: str, native_px: int) -> Iterator[int]:  # noqa: ARG002
        yield native_px

    def to_raw(self, luma: np.ndarray, cam_name: str) -> np.ndarray:  # noqa: ARG002
        return luma


class TrueLens:
    """The true raw cameras of the pairs in ``models`` at ``native_px`` (models hold the mounting rotation as
    ``T_rover_cam``; a pair without models cannot be drawn through this lens). ``render_oversample`` and
    ``hazcam_max_off_axis_deg`` are ``[sensors.lens]``'s (:mod:`rover_sim.scenario.lens_spec`)."""

    def __init__(
        self, models: dict[str, CameraModel], render_oversample: float, hazcam_max_off_axis_deg: float
    ) -> None:
        self.models = models
        # above 1x, a raw pixel integrates over its area of the finer render (a CCD photosite does; a point
        # sample of the finer render would be sharper than any camera): a Gaussian with the variance of a box one
        # raw pixel wide, ``oversample^2 / 12`` render px^2, before the remap
        self.area_sigma_px = render_oversample / math.sqrt(12.0) if render_oversample > 1.0 else 0.0
        self.views: dict[str, RenderView] = {}
        for pair in (p for p in STEREO_PAIRS if f"{p}_left" in models):
            ms = [models[f"{pair}_left"], models[f"{pair}_right"]]
            limit = None if pair == "navcam" else hazcam_max_off_axis_deg
            self.views[pair] = render_view(ms, limit, render_oversample)
        self.max_render_px = max(v.px for v in self.views.values())

    @contextmanager
    def view(self, model: mujoco.MjModel, pair: str, native_px: int) -> Iterator[int]:
        """While drawing ``pair``: the render model's cameras take the wide view; yields the side to render."""
        if pair not in self.views:
            raise ValueError(f"this true lens has no {pair} models (built for: {', '.join(self.views)})")
        v = self.views[pair]
        built_px = next(iter(v.maps.values()))[0].shape[0]
        if native_px != built_px:
            raise ValueError(f"the true lens of {pair} was built for {built_px} px images, not {native_px}: rebuild it")
        ids = [model.camera(f"{pair}_{side}").id for side in ("left", "right")]
        saved = model.cam_fovy[ids].copy()
        model.cam_fovy[ids] = v.fovy_deg
        try:
            yield v.px
        finally:
            model.cam_fovy[ids] = saved

    def to_raw(self, luma: np.ndarray, cam_name: str) -> np.ndarray:
        """Float luminance of the wide pinhole render -> the raw camera's image (native size, float32)."""
        mx, my = self.views[pair_of(cam_name)].maps[cam_name]
        luma = luma.astype(np.float32)
        if self.area_sigma_px > 0.0:
            luma = cv2.GaussianBlur(luma, (0, 0), self.area_sigma_px)
        return cv2.remap(luma, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0.0)  # fmt: skip
