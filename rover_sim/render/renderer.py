"""Offscreen rendering of the rover's stereo cameras: greyscale images, depth and segmentation ground truth.

MER cameras were 1024x1024 12-bit greyscale; navigation used 256x256 images binned (averaged) 4x4. The
:class:`StereoRenderer` offers both reductions (:attr:`RenderConfig.binning`):

* ``binning=1`` (default): render directly at 256x256. About 16x fewer fragments; texture detail is averaged by
  GL mipmapping instead of by the detector, and polygon edges are point-sampled (one sample per pixel, or
  ``multisamples`` of them), so edges alias slightly more than a real binned sensor. The fast choice for
  navigation runs.
* ``binning=4``: render 1024x1024 and average 4x4 blocks, as the MER flight cameras did: correct pixel-area
  integration of texture and edges, but 4-5x slower on a software rasteriser.

Speed (llvmpipe: Mesa's CPU rasteriser; its vertex stage is single-threaded): the cost is the triangle count times
the number of passes (ambient, shadow map and sunlit passes with shadows on, one pass without), and a 20 m x 20 m
terrain at 5 cm is 320k triangles. So the renderer draws from a *render model* (``render_world.py``): the physics
model plus render-only terrain tiles (``terrain_tile_*`` meshes about 1.6 m square, each at several levels of
detail, with world-fixed texture coordinates, drawn in place of the physics hfield, which they reproduce exactly at
level 0). Before each render it hides the tiles and rocks that can neither appear in a camera nor cast a shadow into
it, and draws each remaining tile at the coarsest level whose height error stays below ``lod_tolerance_px`` pixels
and ``lod_max_depth_error`` of the range (:class:`~rover_sim.render.tiles.TerrainTiles`). The physics model is never
modified; the render model's state is copied from ``sim.data`` before each render. The directional sun's shadow map
covers a square ``2 * shadow_half_extent_m`` wide (perpendicular to the sunlight; ``hazcam_shadow_half_extent_m``
for the hazcams) centred ahead of the cameras: the light is re-aimed for every render.

Lighting: the sun (directional, diffuse ``sun_intensity``, casts shadows) plus a uniform sky term
(``sky_ambient``, the MuJoCo headlight's ambient part; its diffuse part is off so nothing is lit from the camera).
Shadows are therefore ``sky_ambient / (sky_ambient + sun_intensity * cos(incidence))`` as bright as lit ground.

Pixel values: luminance ``Y = 0.299 R + 0.587 G + 0.114 B`` of the rendered RGB; with :class:`ImageNoise`, Gaussian
read noise is added in 12-bit counts, the signal is quantised to 12 bits (0-4095) and then scaled to 8 bits
(MER downlinked 12-bit images; the navigation software used 8-bit ones).

Lenses (``[sensors.lens]``, flight profile): with a :class:`~rover_sim.render.lens.TrueLens` the pair is rendered as
a wider pinhole view and remapped into the true raw (distorted) cameras before binning and noise (one call in
:meth:`StereoRenderer._grey`); without one (ideal profile) nothing changes.

GL: ``MUJOCO_GL=egl`` (set by ``rover_sim/__init__``); a :class:`StereoRenderer` owns one EGL context for all its
render sizes (``gl.py``). Never ``fork()`` a process after a context exists (spawn workers instead).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from nav.camera import PinholeCamera, StereoRig
from rover_sim.render.cameras import STEREO_PAIRS, camera_model, camera_world_pose, stereo_rig
from rover_sim.render.config import ImageNoise, RenderConfig
from rover_sim.render.gl import check_gl, set_viewport
from rover_sim.render.imaging import ImageFormation
from rover_sim.render.lens import IdentityLens, TrueLens, pair_of
from rover_sim.render.render_world import RenderWorld
from rover_sim.render.window import follow_window
from rover_sim.sim.stream import release_freed_memory

if TYPE_CHECKING:
    from rover_sim.sim.physics import RoverSim
    from terrains import Terrain

LUMA_WEIGHTS = np.array([0.299, 0.587, 0.114], dtype=np.float32)  # Rec. 601 luminance of RGB
DN12_MAX = 4095  # 12-bit camera counts
MAX_TEXTURE_PX = 16384  # largest texture side llvmpipe (and most GPUs) accept
NO_HIT_DEPTH_FRACTION = 0.99  # depth at or beyond this fraction of zfar (1500 m) is sky: returned as inf


@dataclass(frozen=True)
class StereoFrame:
    """One rendered stereo pair: 8-bit greyscale images and the rig (intrinsics/extrinsics) at capture time."""

    t_s: float
    rig: StereoRig
    left: np.ndarray  # (H, W) uint8
    right: np.ndarray  # (H, W) uint8
    meta: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------------------------- appearance


def terrain_texture(
    terrain: Terrain,
    px_per_m: float = 100.0,
    seed: int = 0,
    *,
    fine_soil: bool = False,
    contrast: float = 1.0,
    patches: tuple[tuple[float, float, float, float], ...] = (),
    regolith: str = "classic",
    sun_direction: np.ndarray | None = None,
) -> np.ndarray:
    """RGB uint8 ground texture for ``RoverSim(terrain, texture_rgb=...)``: terrains' albedo times the Mars tint.

    Row 0 is the south edge, column 0 the west edge (``terrains.appearance`` layout), ``px_per_m`` texels per
    metre. 100 px/m (1 cm texels) matches a 256x256 navcam pixel at about 3 m and a hazcam pixel at about 1 m;
    the texture must stay below 16384 px a side.
    """
    from terrains import albedo_texture, texture_rgb_u8

    side_px = 2.0 * max(terrain.half_x_m, terrain.half_y_m) * px_per_m
    if side_px > MAX_TEXTURE_PX:
        raise ValueError(
            f"a {side_px:.0f} px texture exceeds the {MAX_TEXTURE_PX} px GL limit; lower px_per_m to "
            f"{MAX_TEXTURE_PX / (2.0 * max(terrain.half_x_m, terrain.half_y_m)):.0f} or less"
        )
    albedo = albedo_texture(
        terrain, px_per_m, seed, fine_soil=fine_soil, contrast=contrast, patches=patches, regolith=regolith,
        sun_direction=sun_direction,
    )  # fmt: skip
    return texture_rgb_u8(albedo)


def luminance_u8(rgb: np.ndarray) -> np.ndarray:
    """Rec. 601 luminance of an (H, W, 3) uint8 image, rounded to uint8."""
    return np.rint(rgb.astype(np.float32) @ LUMA_WEIGHTS).astype(np.uint8)


def bin_average(image: np.ndarray, factor: int) -> np.ndarray:
    """Average ``factor`` x ``factor`` blocks (MER 1024 -> 256 binning), float32."""
    if factor == 1:
        return image.astype(np.float32)
    h, w = image.shape[:2]
    blocks = image.reshape(h // factor, factor, w // factor, factor, *image.shape[2:])
    return blocks.mean(axis=(1, 3), dtype=np.float32)


def quantise(luma_0_255: np.ndarray, noise: ImageNoise | None, rng: np.random.Generator | None) -> np.ndarray:
    """Float luminance (0-255 scale) to uint8, through 12-bit read noise and quantisation if ``noise`` is set."""
    if noise is None:
        return np.clip(np.rint(luma_0_255), 0, 255).astype(np.uint8)
    assert rng is not None
    dn12 = luma_0_255 * (DN12_MAX / 255.0) + rng.normal(0.0, noise.read_noise_dn12, luma_0_255.shape)
    dn12 = np.clip(np.rint(dn12), 0, DN12_MAX)
    return np.rint(dn12 * (255.0 / DN12_MAX)).astype(np.uint8)


# ---------------------------------------------------------------------------------------------- render model


# ------------------------------------------------------------------------------------------------- renderer


class StereoRenderer:
    """Renders the rover's stereo pairs, depth and segmentation from a :class:`RoverSim`'s current state.

    Owns one :class:`mujoco.Renderer` (one EGL context) for every resolution it rasterises: a render of ``px`` draws
    into the ``px`` x ``px`` viewport at the corner of the context's offscreen framebuffer (the model's ``offwidth``,
    the same buffer a ``px``-sized renderer would draw into, so the pixels are the same). One context per size cost
    ~100-150 MB each on llvmpipe (shadow map, framebuffer, uploaded meshes and texture): the flight lenses draw each
    pair at its own size, so a drive that first images the rear hazcams while backing up grew by a whole context
    (the traverse benchmark's memory bar); one context also means one upload per streamed window move. Created on
    first use and reused; close it (or use it as a context manager) to free it. Camera geometry is taken from the
    physics model, so :meth:`rig` equals :func:`rover_sim.render.cameras.stereo_rig` at the output resolution.
    """

    def __init__(self, sim: RoverSim, config: RenderConfig | None = None, lens: TrueLens | None = None) -> None:
        check_gl()
        self.config = config or RenderConfig()
        self.sim = sim
        self.lens = lens or IdentityLens()  # the true lenses (flight profile): raw images from a wider pinhole view
        self.world = RenderWorld(sim, self.config, self.lens.max_render_px)
        self._sun_direction_world: np.ndarray | None = None  # set_sun's sun, kept across a streamed window's rebuild
        self.shadows = self.config.shadows and sim.sun.shadows  # switch per render: ``renderer.shadows = False``
        self._gl: mujoco.Renderer | None = None  # the one GL context (see the class docstring)
        self._gl_px = 0  # the largest viewport it was created for
        self._rng = np.random.default_rng(self.config.noise.seed) if self.config.noise else None
        im = self.config.imaging
        ccd = im is not None and im.model != "ideal"
        self.imaging = ImageFormation(im, self.config.imaging_seed, self.config.binning) if ccd else None
        self._right_cam = mujoco.MjvCamera()
        self._right_cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self.last_drawn: dict = {}  # what the last render drew (tiles, rocks, tile levels): diagnostics

    # -- lifecycle
    def reseed_noise(self, seed: int | None) -> None:
        """Restart the image-noise generator from ``seed`` (None: noise off for a renderer configured without)."""
        self._rng = np.random.default_rng(seed) if seed is not None and self.config.noise else None

    def close(self) -> None:
        if self._gl is not None:
            self._gl.close()
        self._gl, self._gl_px = None, 0

    @property
    def contexts(self) -> list[mujoco.Renderer]:
        """The live GL contexts (none before the first render or after :meth:`close`; at most one)."""
        return [] if self._gl is None else [self._gl]

    def __enter__(self) -> StereoRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _renderer(self, px: int) -> mujoco.Renderer:
        r = self._gl
        if r is None or px > self._gl_px:  # the first render, or a larger one than the context was made for
            self.close()
            self._gl_px = max(px, self.lens.max_render_px, self.config.native_px, self.config.resolution_px)
            r = self._gl = mujoco.Renderer(self.world.model, self._gl_px, self._gl_px)
        set_viewport(r, px)
        sc = r.scene
        sc.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = self.shadows
        sc.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = self.config.skybox
        sc.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        sc.flags[mujoco.mjtRndFlag.mjRND_FOG] = False
        sc.flags[mujoco.mjtRndFlag.mjRND_HAZE] = False
        return r

    def set_sun(self, direction_world: np.ndarray) -> None:
        """Point the sun along unit ``direction_world`` (the way sunlight travels) for the next renders."""
        self._sun_direction_world = np.asarray(direction_world, dtype=float).copy()
        self.world.model.light_dir[self.world.sun_id] = self._sun_direction_world

    def set_ground_texture(self, texture_rgb: np.ndarray) -> None:
        """Replace the terrain texture (same size; ``terrain_texture`` layout) in the model and every GL context."""
        m = self.world.model
        tid = m.texture("terrain_albedo").id
        adr, h, w = int(m.tex_adr[tid]), int(m.tex_height[tid]), int(m.tex_width[tid])
        if texture_rgb.shape != (h, w, 3):
            raise ValueError(f"ground texture must be {(h, w, 3)}, got {texture_rgb.shape}")
        m.tex_data[adr : adr + h * w * 3] = np.ascontiguousarray(texture_rgb[::-1], dtype=np.uint8).ravel()
        self.close()  # the GL contexts are re-created on the next render and upload the new texture (rare: re-bakes)

    # -- cameras
    def rig(self, pair: str) -> StereoRig:
        """Stereo rig of ``pair`` at the output resolution, from the simulation's current state."""
        return stereo_rig(self.sim.model, self.sim.data, pair, self.config.resolution_px)

    def camera(self, cam_name: str, resolution_px: int | None = None) -> PinholeCamera:
        px = resolution_px or self.config.resolution_px
        return camera_model(self.sim.model, self.sim.data, cam_name, px, px)

    # -- rendering core
    def _scene_for(self, cam_names: list[str], px: int, lit: bool = True) -> mujoco.Renderer:
        """Sync state, cull for all ``cam_names``, build the scene for the first camera; returns the renderer.

        ``lit=False`` (depth, segmentation): no shadow casters outside the view are needed.
        """
        if self.world.terrain_version != self.sim.terrain_version:  # streamed terrain: the window moved
            if not follow_window(self.world, self.contexts, self.sim.window_texture_rgb()):  # moved in place
                self.close()
                self.world = RenderWorld(self.sim, self.config, self.lens.max_render_px)
                if self._sun_direction_world is not None:  # a moved sun (mission clock): not the model's start sun
                    self.world.model.light_dir[self.world.sun_id] = self._sun_direction_world
            release_freed_memory()  # the previous window's tile meshes and texture (see sim/stream.py)
        w = self.world
        w.ruts.refresh(self.contexts)  # no-op without [physics] deformable
        w.sync()
        cams = [camera_model(w.model, w.data, n, px, px) for n in cam_names]
        poses = [camera_world_pose(w.model, w.data, n) for n in cam_names]
        half = self.config.shadow_half_extent_for(cam_names[0])
        self.last_drawn = w.prepare(cams, poses, self.shadows and lit, half)
        r = self._renderer(px)
        r._mjr_context.shadowClip = half  # the directional light's shadow box (read at every mjr_render)
        r.update_scene(w.data, camera=cam_names[0], scene_option=w.option)
        return r

    def _switch_camera(self, r: mujoco.Renderer, cam_name: str) -> None:
        """Point the already-built scene at another camera (geometry, culling and lights unchanged)."""
        self._right_cam.fixedcamid = self.world.model.camera(cam_name).id
        mujoco.mjv_updateCamera(self.world.model, self.world.data, self._right_cam, r.scene)

    def _grey(self, rgb: np.ndarray, cam_name: str) -> np.ndarray:
        luma = self.lens.to_raw(rgb.astype(np.float32) @ LUMA_WEIGHTS, cam_name)  # raw geometry (lens.py)
        if self.imaging is not None:  # flight: exposure, photons, noise, ADC, binning, companding (imaging.py)
            return self.imaging.form(luma, cam_name)
        return quantise(bin_average(luma, self.config.binning), self.config.noise, self._rng)

    # -- public renders
    def render_pair(self, pair: str = "navcam") -> StereoFrame:
        """Greyscale stereo pair (uint8, ``resolution_px`` square) of ``pair`` at the simulation's current state.

        With a :class:`~rover_sim.render.lens.TrueLens` the images are raw (distorted, unrectified) and ``rig`` is
        still the MJCF pinhole rig (the render geometry, not a model of the raw images)."""
        if pair not in STEREO_PAIRS:
            raise ValueError(f"unknown stereo pair {pair!r}; choose one of {STEREO_PAIRS}")
        names = [f"{pair}_left", f"{pair}_right"]
        with self.lens.view(self.world.model, pair, self.config.native_px) as px:
            r = self._scene_for(names, px)
            left = self._grey(r.render(), names[0])
            self._switch_camera(r, names[1])
            right = self._grey(r.render(), names[1])
        return StereoFrame(self.sim.time_s, self.rig(pair), left, right, dict(self.last_drawn))

    def render_rgb(self, cam_name: str, resolution_px: int | None = None) -> np.ndarray:
        """(H, W, 3) uint8 colour image of one camera (no binning, no noise): for logging and debugging."""
        px = resolution_px or self.config.resolution_px
        return self._scene_for([cam_name], px).render()

    def render_grey(self, cam_name: str) -> np.ndarray:
        """Greyscale image of one camera, processed like :meth:`render_pair` (binning, noise)."""
        with self.lens.view(self.world.model, pair_of(cam_name), self.config.native_px) as px:
            return self._grey(self._scene_for([cam_name], px).render(), cam_name)

    def render_depth(self, cam_name: str, resolution_px: int | None = None) -> np.ndarray:
        """(H, W) float32 z-depth in metres along the optical axis (OpenCV z) at pixel centres; inf = sky.

        Rendered directly at the output resolution (never binned: averaging depth across edges is meaningless).
        MuJoCo's depth buffer holds the distance along the camera's -z axis, which is the OpenCV +z depth.
        """
        px = resolution_px or self.config.resolution_px
        r = self._scene_for([cam_name], px, lit=False)
        r.enable_depth_rendering()
        try:
            depth = r.render()
        finally:
            r.disable_depth_rendering()
        far = self.world.model.vis.map.zfar * self.world.model.stat.extent
        depth[depth >= NO_HIT_DEPTH_FRACTION * far] = np.inf
        return depth

    def render_segmentation(self, cam_name: str, resolution_px: int | None = None) -> np.ndarray:
        """(H, W) int32 geom id **of the physics model** seen at each pixel (terrain tiles -> ``terrain``); -1 sky."""
        px = resolution_px or self.config.resolution_px
        r = self._scene_for([cam_name], px, lit=False)
        r.enable_segmentation_rendering()
        try:
            seg = r.render()
        finally:
            r.disable_segmentation_rendering()
        ids = np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)
        return self.world.geom_to_phys[ids]  # -1 indexes the LUT's last entry, which is -1
