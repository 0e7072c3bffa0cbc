"""The render model: the physics model plus render-only geometry (LOD terrain tiles, textured rocks), with its own
MjData kept in step with the simulation's; before each render it hides what no camera sees (see
:mod:`rover_sim.render.renderer`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import mujoco
import numpy as np

from nav.camera import PinholeCamera
from rover_sim.render.config import RenderConfig
from rover_sim.render.ruts import TileRuts
from rover_sim.render.tiles import (
    GROUP_HIDDEN,
    GROUP_SHOWN,
    TILE_PREFIX,
    add_terrain_tiles,
)
from rover_sim.sim.assembly import ROCK_GEOM_PREFIX

if TYPE_CHECKING:
    from rover_sim.sim.physics import RoverSim
    from terrains import Terrain

ROCK_MATERIAL = "rock_textured"
ROCK_TINT_RGB = (0.82, 0.70, 0.60)  # dust-coated basalt: greyer than the butterscotch soil
ROCK_TEXTURE = "rock_speckle"
ROCK_TEXTURE_PX = 128
ROCK_TEXTURE_SCALE_M = 0.3  # one repeat of the rock speckle texture spans this many metres
ROCK_TEXTURE_SLANT = 0.6  # texcoords use x + 0.6 z and y + 0.6 z so steep rock sides are not stretched
ROCK_SPECKLE_CONTRAST = 0.18  # std of the rock speckle texture, relative
SUN_DISTANCE_MARGIN_M = 20.0  # the shadow camera sits this far beyond the scene along the sunlight


def rock_rgba(rock: object, seed: int) -> list[float]:
    """A rock's colour: its own grey level (``terrains.rock_albedo``) times the dusty-basalt tint."""
    from terrains import rock_albedo

    return [*(rock_albedo(rock, seed) * np.asarray(ROCK_TINT_RGB)), 1.0]


def slot_box(rock: object) -> list[np.ndarray]:
    """World AABB (min, max) of a streamed rock slot (an ellipsoid primitive) from its footprint and height."""
    r = rock.footprint_radius_m  # type: ignore[attr-defined]
    x, y, z, h = rock.x_m, rock.y_m, rock.z_base_m, rock.height_m  # type: ignore[attr-defined]
    return [np.array([x - r, y - r, z - h]), np.array([x + r, y + r, z + h])]


def _rock_appearance(spec: mujoco.MjSpec, terrain: Terrain) -> tuple[list[str], np.ndarray]:
    """Give each rock its own grey level (``terrains.rock_albedo``) and a speckle texture; return AABBs."""
    rng = np.random.default_rng(terrain.seed + 7919)
    noise = np.fft.fft2(rng.normal(0.0, 1.0, (ROCK_TEXTURE_PX, ROCK_TEXTURE_PX)))
    freq = np.fft.fftfreq(ROCK_TEXTURE_PX)
    blur = np.exp(-2.0 * np.pi**2 * (freq[:, None] ** 2 + freq[None, :] ** 2))  # Gaussian, sigma 1 px, periodic
    speckle = np.real(np.fft.ifft2(noise * blur))
    level = np.clip(0.82 + ROCK_SPECKLE_CONTRAST * speckle / speckle.std(), 0.0, 1.0)
    tex = spec.add_texture()
    tex.name, tex.type = ROCK_TEXTURE, mujoco.mjtTexture.mjTEXTURE_2D
    tex.width, tex.height, tex.nchannel = ROCK_TEXTURE_PX, ROCK_TEXTURE_PX, 3
    tex.data = np.rint(np.repeat(level[..., None], 3, axis=-1) * 255).astype(np.uint8).tobytes()
    mat = spec.add_material()
    mat.name = ROCK_MATERIAL
    textures = [""] * len(mat.textures)
    textures[int(mujoco.mjtTextureRole.mjTEXROLE_RGB)] = ROCK_TEXTURE
    mat.textures = textures
    mat.specular, mat.shininess = 0.0, 0.0

    names, boxes = [], []
    for i, rock in enumerate(terrain.rocks):
        name = f"{ROCK_GEOM_PREFIX}{i:04d}"
        mesh = spec.mesh(name)
        if mesh is None:  # a streamed rock slot: an ellipsoid primitive (sim/assembly.py), boxed by its footprint
            verts = np.array(slot_box(rock))
        else:
            verts = np.asarray(mesh.uservert, dtype=float).reshape(-1, 3)
            s = verts[:, :2] + ROCK_TEXTURE_SLANT * verts[:, 2:3]
            mesh.usertexcoord = (s / ROCK_TEXTURE_SCALE_M).ravel().tolist()
        g = spec.geom(name)
        g.material, g.group = ROCK_MATERIAL, GROUP_SHOWN
        g.rgba = rock_rgba(rock, terrain.seed)
        names.append(name)
        boxes.append([verts.min(axis=0), verts.max(axis=0)])
    return names, np.asarray(boxes).reshape(-1, 2, 3)


def _geom_id_map(render_model: mujoco.MjModel, phys_model: mujoco.MjModel) -> np.ndarray:
    """Render-model geom id -> physics geom id (tiles -> the terrain hfield), by (body, order within body)."""

    def keys(m: mujoco.MjModel) -> list[tuple[int, int]]:
        count: dict[int, int] = {}
        out = []
        for b in m.geom_bodyid:
            out.append((int(b), count.get(int(b), 0)))
            count[int(b)] = count.get(int(b), 0) + 1
        return out

    phys = {k: g for g, k in enumerate(keys(phys_model))}
    terrain_id = phys_model.geom("terrain").id
    lut = np.full(render_model.ngeom + 1, -1, dtype=np.int32)  # last entry: background (-1)
    for g, k in enumerate(keys(render_model)):
        name = render_model.geom(g).name
        lut[g] = terrain_id if name.startswith(TILE_PREFIX) else phys[k]
    return lut


class RenderWorld:
    """The physics model plus render-only geometry, with its own MjData kept in step with the simulation's."""

    def __init__(self, sim: RoverSim, config: RenderConfig, offscreen_px: int = 0) -> None:
        self.sim, self.config = sim, config
        self.terrain_version = sim.terrain_version  # a streamed terrain's window this model shows
        spec = sim.spec.copy()
        self.tiles = add_terrain_tiles(
            spec, sim.terrain, config.terrain_tile_m, config.max_terrain_tiles, config.terrain_casts_shadows
        )
        rock_names, self.rock_boxes = _rock_appearance(spec, sim.terrain)
        spec.geom("terrain").group = GROUP_HIDDEN  # drawn as tiles instead
        light = spec.light("sun")
        light.castshadow = True  # shadows are switched per render with the scene flag
        light.diffuse = [config.sun_intensity] * 3
        light.ambient, light.specular = [0.0] * 3, [0.0] * 3
        vis = spec.visual
        vis.headlight.diffuse, vis.headlight.specular = [0.0] * 3, [0.0] * 3
        vis.headlight.ambient = [config.sky_ambient] * 3
        vis.quality.shadowsize = config.shadow_map_px
        vis.quality.offsamples = config.multisamples
        vis.quality.numslices, vis.quality.numstacks = config.builtin_slices, config.builtin_stacks
        vis.map.shadowclip = config.shadow_half_extent_m / spec.stat.extent
        vis.global_.offwidth = vis.global_.offheight = max(config.native_px, 1024, offscreen_px)  # + lens
        self.model = spec.compile()
        if sim.streamer is not None:
            sim.streamer.apply(self.model, sim.terrain)  # true window heights and rock slots (render-only hfield)
        self.data = mujoco.MjData(self.model)
        if self.model.nq != sim.model.nq or self.model.nbody != sim.model.nbody:
            raise RuntimeError("render model layout differs from the physics model (render-only geoms only!)")
        m = self.model
        self.tile_ids = self.tiles.geom_ids(m)
        self.ruts = TileRuts(m, self.tiles, sim)  # deformable terrain: tiles re-meshed where the ground changed
        self.rock_ids = np.array([m.geom(n).id for n in rock_names], dtype=np.int32)
        self.geom_to_phys = _geom_id_map(m, sim.model)
        self.sun_id = m.light("sun").id
        self.floor_z = float(sim.terrain.heights_m.min())
        self.option = mujoco.MjvOption()
        self.option.geomgroup[:] = 0
        self.option.geomgroup[[GROUP_SHOWN, 2]] = 1  # terrain tiles and rocks, rover visuals

    def sync(self) -> None:
        """Copy the simulation state and recompute poses (kinematics, cameras, lights)."""
        self.data.qpos[:] = self.sim.data.qpos
        self.data.time = self.sim.data.time
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)

    def prepare(
        self, cams: list[PinholeCamera], T_world_cams: list[np.ndarray], shadows: bool, shadow_half_m: float
    ) -> dict:
        """Pick what to draw for these cameras (culling, tile levels) and aim the shadow box; returns counts."""
        cfg = self.config
        light_dir = self.data.light_xdir[self.sun_id].copy()
        n_tiles = len(self.tiles.boxes)
        boxes = np.concatenate([self.tiles.boxes, self.rock_boxes])
        if shadows and cfg.cull:  # a geom can shade the view from outside it: sweep its box along the sunlight
            casters = slice(0 if cfg.terrain_casts_shadows else n_tiles, None)
            b = boxes[casters]
            reach = np.clip((b[:, 1, 2] - self.floor_z) / max(-light_dir[2], 0.05), 0.0, 4.0 * shadow_half_m)
            swept = b[:, None, :, :] + np.stack([np.zeros_like(reach), reach], axis=1)[:, :, None, None] * light_dir
            boxes[casters] = np.stack([swept.min(axis=(1, 2)), swept.max(axis=(1, 2))], axis=1)
        shown = np.ones(len(boxes), dtype=bool)
        if cfg.cull:
            shown[:] = False
            for cam, T in zip(cams, T_world_cams, strict=True):
                shown |= boxes_in_view(boxes, cam, T)
        tiles_shown, rocks_shown = shown[:n_tiles], shown[n_tiles:]
        if cfg.lod:
            level = self.tiles.choose_levels(self._lod_allowance_m(cams[0], T_world_cams))
        else:
            level = np.zeros(n_tiles, dtype=int)
        groups = self.model.geom_group
        groups[self.tile_ids[self.tile_ids >= 0]] = GROUP_HIDDEN
        sel = np.flatnonzero(tiles_shown)
        groups[self.tile_ids[sel, level[sel]]] = GROUP_SHOWN
        groups[self.rock_ids] = np.where(rocks_shown, GROUP_SHOWN, GROUP_HIDDEN)
        self._aim_sun(T_world_cams[0], light_dir, shadow_half_m)
        return {"tiles_drawn": int(tiles_shown.sum()), "rocks_drawn": int(rocks_shown.sum()),
                "tile_levels": np.bincount(level[sel], minlength=self.tiles.error_m.shape[1]).tolist()}  # fmt: skip

    def _lod_allowance_m(self, cam: PinholeCamera, T_world_cams: list[np.ndarray]) -> np.ndarray:
        """Largest tolerable height error per tile: the smaller of an image-space bound (``lod_tolerance_px`` at
        the tile's distance) and a range bound: a height error ``e`` moves the range ``r`` of a ray meeting the
        ground at angle ``a`` by ``e / sin(a)``, and ``r sin(a)`` is the camera's distance to the tile's plane,
        so ``e <= lod_max_depth_error * distance_to_plane`` keeps the range error below that fraction.
        """
        cfg, tiles = self.config, self.tiles
        allowed = np.full(len(tiles.boxes), np.inf)
        for T in T_world_cams:
            image = cfg.lod_tolerance_px / cam.fx_px * box_distance(tiles.boxes, T[:3, 3])
            to_plane = np.abs(np.einsum("ij,ij->i", tiles.centres - T[:3, 3], tiles.normals))
            allowed = np.minimum(allowed, np.minimum(image, cfg.lod_max_depth_error * to_plane))
        return allowed

    def _aim_sun(self, T_world_cam: np.ndarray, light_dir: np.ndarray, half: float) -> None:
        """Centre the directional light's shadow box on the ground ahead of the camera."""
        fwd = T_world_cam[:3, 2].copy()
        fwd[2] = 0.0
        norm = np.linalg.norm(fwd)
        fwd = fwd / norm if norm > 1e-6 else np.zeros(3)
        centre = T_world_cam[:3, 3] + 0.5 * half * fwd
        centre[2] = float(self.sim.terrain.height_at(centre[0], centre[1]))
        self.data.light_xpos[self.sun_id] = centre - light_dir * (2.0 * half + SUN_DISTANCE_MARGIN_M)


def box_distance(boxes: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(N,) distance from ``point`` to each axis-aligned box ``(N, 2, 3)`` (0 inside)."""
    gap = np.maximum(np.maximum(boxes[:, 0] - point, point - boxes[:, 1]), 0.0)
    return np.linalg.norm(gap, axis=1)


def boxes_in_view(boxes: np.ndarray, cam: PinholeCamera, T_world_cam: np.ndarray, near_m: float = 0.0) -> np.ndarray:
    """(N,) bool: axis-aligned boxes ``(N, 2, 3)`` (min, max corners, world) that may intersect the view frustum.

    Conservative: a box is rejected only when all 8 corners lie outside one frustum side plane.
    """
    corners = np.stack(
        [np.stack([boxes[:, i, 0], boxes[:, j, 1], boxes[:, k, 2]], axis=-1)
         for i in (0, 1) for j in (0, 1) for k in (0, 1)], axis=1)  # fmt: skip
    R, c = T_world_cam[:3, :3], T_world_cam[:3, 3]
    p = (corners - c) @ R  # camera frame
    # inward normals of the side planes (through the optical centre) and the near plane
    hw, hh = 0.5 * cam.width_px + 1.0, 0.5 * cam.height_px + 1.0
    planes = np.array([[cam.fx_px, 0, hw], [-cam.fx_px, 0, hw], [0, cam.fy_px, hh], [0, -cam.fy_px, hh], [0, 0, 1]])
    offsets = np.array([0, 0, 0, 0, near_m])
    inside = p @ planes.T - offsets >= 0.0  # (N, 8, 5)
    return inside.any(axis=1).all(axis=1)
