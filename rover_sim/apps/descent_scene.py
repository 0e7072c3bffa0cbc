"""The DIMES descent scene: the MuJoCo model (terrain heightfield, texture, sun, descent camera) and its renderer.

:class:`DescentCameraConfig` is the MER descent imager (see :mod:`rover_sim.apps.descent` for the scenario).
MuJoCo scales the clip planes by ``statistic/extent``: extent 1000 m with ``znear=0.01``, ``zfar=10`` gives 10 m
to 10 km.

GL: one :class:`DescentRenderer` owns one EGL context; never ``fork()`` after it exists.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from nav.camera import PinholeCamera
from nav.geometry import R_to_quat_wxyz
from rover_sim.render.cameras import MJ_TO_CV
from rover_sim.render.config import ImageNoise
from rover_sim.render.gl import check_gl
from rover_sim.render.renderer import LUMA_WEIGHTS, bin_average, quantise
from rover_sim.sim.assembly import Sun, hfield_encoding

if TYPE_CHECKING:
    from terrains import Terrain

CLIP_EXTENT_M = 1000.0  # MuJoCo statistic/extent: znear and zfar are multiples of it
ZNEAR, ZFAR = 0.01, 10.0  # -> clip planes at 10 m and 10 km
SUN_DIFFUSE = 1.3  # diffuse strength of the sun (as rover_sim.render.renderer)
SKY_AMBIENT = 0.45  # uniform ambient light standing in for the dusty sky


@dataclass(frozen=True)
class DescentCameraConfig:
    """MER descent imager: 45 deg field of view, 1024x1024 12-bit; DIMES used 256x256.

    See :mod:`rover_sim.apps.descent` (module docstring).
    """

    resolution_px: int = 256
    binning: int = 1  # 1: render at resolution_px; 4: render 1024 and average 4x4 (detector binning)
    fov_deg: float = 45.0
    read_noise_dn12: float = 3.0  # rms read noise in 12-bit counts (0: quantisation only), as rover_sim.render.renderer

    @property
    def native_px(self) -> int:
        return self.resolution_px * self.binning

    def camera(self) -> PinholeCamera:
        return PinholeCamera.from_fov("descent_camera", self.resolution_px, self.resolution_px, self.fov_deg)


_SCENE_XML = f"""
<mujoco model="dimes descent">
  <statistic center="0 0 0" extent="{CLIP_EXTENT_M}"/>
  <visual>
    <headlight diffuse="0 0 0" ambient="{SKY_AMBIENT} {SKY_AMBIENT} {SKY_AMBIENT}" specular="0 0 0"/>
    <map znear="{ZNEAR}" zfar="{ZFAR}"/>
    <global offwidth="1024" offheight="1024"/>
  </visual>
  <asset>
    <texture name="ground_albedo" type="2d" builtin="flat" rgb1="0.76 0.55 0.40" width="8" height="8"/>
    <material name="ground" texture="ground_albedo" specular="0" shininess="0" reflectance="0"/>
    <hfield name="ground" nrow="2" ncol="2" size="10 10 1 1"/>
  </asset>
  <worldbody>
    <light name="sun" directional="true" castshadow="false" pos="0 0 3000" dir="0 0 -1"
           diffuse="{SUN_DIFFUSE} {SUN_DIFFUSE} {SUN_DIFFUSE}" specular="0 0 0"/>
    <geom name="ground" type="hfield" hfield="ground" material="ground" contype="0" conaffinity="0"/>
    <camera name="descent_camera" pos="0 0 2000" fovy="45"/>
  </worldbody>
</mujoco>
"""


def descent_model(
    terrain: Terrain, texture_rgb: np.ndarray, sun: Sun, camera: DescentCameraConfig | None = None
) -> mujoco.MjModel:
    """MuJoCo model: the terrain heightfield with the texture draped over it, the sun, the descent camera."""
    camera = camera or DescentCameraConfig()
    spec = mujoco.MjSpec.from_string(_SCENE_XML)
    spec.visual.global_.offwidth = spec.visual.global_.offheight = max(1024, camera.native_px)
    data, elev_range_m, base_z_m = hfield_encoding(terrain.heights_m)
    hf = spec.hfield("ground")
    hf.nrow, hf.ncol = terrain.heights_m.shape
    hf.size = [terrain.half_x_m, terrain.half_y_m, elev_range_m, 10.0]
    hf.userdata = data.ravel().tolist()
    spec.geom("ground").pos = [0.0, 0.0, base_z_m]
    tex = spec.texture("ground_albedo")
    h, w, _ = texture_rgb.shape
    tex.builtin = mujoco.mjtBuiltin.mjBUILTIN_NONE
    tex.width, tex.height, tex.nchannel = w, h, 3
    tex.data = np.ascontiguousarray(texture_rgb[::-1], dtype=np.uint8).tobytes()  # hfield row 0 is north in GL
    spec.light("sun").dir = sun.direction().tolist()
    spec.camera("descent_camera").fovy = camera.fov_deg
    return spec.compile()


class DescentRenderer:
    """Renders the descent camera at a given pose; owns one EGL context (created on first use)."""

    def __init__(self, terrain: Terrain, texture_rgb: np.ndarray, camera: DescentCameraConfig | None = None) -> None:
        check_gl()
        self.terrain = terrain
        self.config = camera or DescentCameraConfig()
        self.model = descent_model(terrain, texture_rgb, Sun(shadows=False), self.config)
        self.data = mujoco.MjData(self.model)
        self._renderer: mujoco.Renderer | None = None
        self._cam_id = self.model.camera("descent_camera").id
        self._sun_id = self.model.light("sun").id

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> DescentRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def render(self, T_world_cam: np.ndarray, sun: Sun, noise: ImageNoise | None = None) -> np.ndarray:
        """(H, W) uint8 greyscale image from camera pose ``T_world_cam`` (OpenCV axes) under ``sun``."""
        self.model.cam_pos[self._cam_id] = T_world_cam[:3, 3]
        self.model.cam_quat[self._cam_id] = R_to_quat_wxyz(T_world_cam[:3, :3] @ MJ_TO_CV)
        self.model.light_dir[self._sun_id] = sun.direction()
        mujoco.mj_forward(self.model, self.data)
        if self._renderer is None:
            px = self.config.native_px
            self._renderer = mujoco.Renderer(self.model, px, px)
        r = self._renderer
        for flag in ("mjRND_SHADOW", "mjRND_REFLECTION", "mjRND_FOG", "mjRND_HAZE", "mjRND_SKYBOX"):
            r.scene.flags[getattr(mujoco.mjtRndFlag, flag)] = False
        r.update_scene(self.data, camera="descent_camera")
        luma = bin_average(r.render().astype(np.float32) @ LUMA_WEIGHTS, self.config.binning)
        rng = np.random.default_rng(noise.seed) if noise is not None else None
        return quantise(luma, noise, rng)
