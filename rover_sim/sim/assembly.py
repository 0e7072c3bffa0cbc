"""World assembly: the MER model + a synthesised terrain (heightfield, rocks, appearance) + the sun, via MjSpec."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from rover_sim.resources import models_dir

if TYPE_CHECKING:
    from terrains import Rock, Terrain


MODELS_DIR = models_dir()
SCENE_XML = MODELS_DIR / "mer" / "scene.xml"
ROVER_XML = MODELS_DIR / "mer" / "rover.xml"

HFIELD_BASE_M = 1.0  # thickness of the heightfield slab below its lowest point
ROCK_GEOM_PREFIX = "rock_"


@dataclass(frozen=True)
class Sun:
    """A directional light. Azimuth from +x (east) toward +y (north), elevation above the horizon."""

    azimuth_deg: float = 135.0
    elevation_deg: float = 45.0
    shadows: bool = True

    def direction(self) -> np.ndarray:
        """Unit vector along which sunlight travels (from the sun toward the ground)."""
        az, el = np.radians(self.azimuth_deg), np.radians(self.elevation_deg)
        to_sun = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        return -to_sun


def hfield_encoding(heights_m: np.ndarray, range_m: float | None = None) -> tuple[np.ndarray, float, float]:
    """MuJoCo stores heights normalised to [0, 1] times ``size[2]`` above the geom's z: returns
    (normalised data, elevation range m, base z m). A fixed ``range_m`` (streamed windows) clips above it."""
    h_min, h_max = float(heights_m.min()), float(heights_m.max())
    rng = max(h_max - h_min, 1e-3) if range_m is None else float(range_m)
    if range_m is not None:
        return np.clip((heights_m - h_min) / rng, 0.0, 1.0).astype(np.float32), rng, h_min
    return ((heights_m - h_min) / rng).astype(np.float32), rng, h_min


def build_spec(
    terrain: Terrain,
    sun: Sun | None = None,
    texture_rgb: np.ndarray | None = None,
    texture_size_m: float | None = None,
    rock_slots: int | None = None,
    elevation_range_m: float | None = None,
) -> mujoco.MjSpec:
    """Scene spec with the terrain's heightfield, one mesh geom per rock and the sun.

    ``texture_rgb`` (H, W, 3) uint8, if given, is draped over the whole terrain (``texture_size_m`` per repeat,
    default the terrain's extent), so the albedo is world-fixed as stereo and VO require. It follows the
    ``terrains.albedo_texture`` layout: row 0 is the south edge (smallest y), column 0 the west edge (smallest x).

    Streamed terrains (``rover_sim/sim/stream.py``): the hfield sits at ``terrain.origin_xy_m`` with a fixed
    ``elevation_range_m`` (so later windows fit the same encoding), and the rocks are a pool of ``rock_slots``
    ellipsoid geoms that can be moved and resized in place (:func:`rock_slot_geometry`).
    """
    sun = sun or Sun()
    spec = mujoco.MjSpec.from_file(str(SCENE_XML))
    data, elev_range_m, base_z_m = hfield_encoding(terrain.heights_m, elevation_range_m)
    hf = spec.hfield("terrain")
    hf.nrow, hf.ncol = terrain.heights_m.shape
    hf.size = [terrain.half_x_m, terrain.half_y_m, elev_range_m, HFIELD_BASE_M]
    hf.userdata = data.ravel().tolist()
    geom = spec.geom("terrain")
    geom.pos = [*terrain.origin_xy_m, base_z_m]

    if texture_rgb is not None:
        tex = spec.texture("terrain_albedo")
        h, w, _ = texture_rgb.shape
        tex.builtin = mujoco.mjtBuiltin.mjBUILTIN_NONE
        tex.width, tex.height, tex.nchannel = w, h, 3
        # MuJoCo's hfield texture mapping puts the first data row at +y (north): flip so row 0 lies south.
        tex.data = np.ascontiguousarray(texture_rgb[::-1], dtype=np.uint8).tobytes()
        mat = spec.material("terrain")
        rep = (texture_size_m or 2 * terrain.half_x_m, texture_size_m or 2 * terrain.half_y_m)
        mat.texrepeat = [2 * terrain.half_x_m / rep[0], 2 * terrain.half_y_m / rep[1]]
        mat.texuniform = False

    if rock_slots is not None:
        _add_rock_slots(spec, terrain, rock_slots)
    for i, rock in enumerate(terrain.rocks if rock_slots is None else ()):
        mesh = rock.mesh()
        name = f"{ROCK_GEOM_PREFIX}{i:04d}"
        spec.add_mesh(
            name=name,
            uservert=np.asarray(mesh.vertices, dtype=float).ravel().tolist(),
            userface=np.asarray(mesh.faces, dtype=int).ravel().tolist(),
        )
        g = spec.worldbody.add_geom()
        g.name = name
        g.type = mujoco.mjtGeom.mjGEOM_MESH
        g.meshname = name
        g.material = "rock"
        g.contype, g.conaffinity, g.condim = 0, 1, 3
        g.friction = [0.8, 0.02, 0.001]
        g.group = 0

    light = spec.light("sun")
    light.dir = sun.direction().tolist()
    light.castshadow = sun.shadows
    return spec


PARKED_DEPTH_M = 200.0  # an unused rock slot waits this far below the hfield's base, out of every contact
PARKED_SIZE_M = 0.01
SITE_HALF_EXTENT_M = 20_000.0  # a streamed site stays within this of the origin (world body bound, see below)


def rock_slot_geometry(rock: Rock | None, park_xyz_m: tuple[float, float, float]) -> tuple[list, list, list]:
    """(pos, quat wxyz, ellipsoid half-axes) of a rock slot: the rock's ellipsoid centred on its base (the lower
    half is its buried part), or a tiny parked ellipsoid."""
    if rock is None:
        return list(park_xyz_m), [1.0, 0.0, 0.0, 0.0], [PARKED_SIZE_M] * 3
    half = 0.5 * rock.yaw_rad
    return ([rock.x_m, rock.y_m, rock.z_base_m], [float(np.cos(half)), 0.0, 0.0, float(np.sin(half))],
            [0.5 * rock.length_m, 0.5 * rock.width_m, rock.height_m])  # fmt: skip


def park_point_m(terrain: Terrain) -> tuple[float, float, float]:
    ox, oy = terrain.origin_xy_m
    return (ox, oy, float(np.min(terrain.heights_m)) - PARKED_DEPTH_M)


def _add_rock_slots(spec: mujoco.MjSpec, terrain: Terrain, slots: int) -> None:
    """``slots`` ellipsoid rock geoms (streamed terrains): the terrain's rocks first, the rest parked.

    MuJoCo bounds the world body's static geoms at compile time (its bounding-volume tree), so geoms moved later
    would fall outside it and lose their contacts: the streamer rebuilds that tree after every move
    (``sim/bvh.py``), and the last two slots are compiled at opposite corners ``SITE_HALF_EXTENT_M`` away so the
    world body's bound covers the whole site from the start.
    """
    park = park_point_m(terrain)
    corners = {slots - 1: (SITE_HALF_EXTENT_M, SITE_HALF_EXTENT_M, SITE_HALF_EXTENT_M),
               slots - 2: (-SITE_HALF_EXTENT_M, -SITE_HALF_EXTENT_M, -SITE_HALF_EXTENT_M)}  # fmt: skip
    for i in range(slots):
        rock = terrain.rocks[i] if i < len(terrain.rocks) else None
        pos, quat, size = rock_slot_geometry(rock, corners.get(i, park) if rock is None else park)
        g = spec.worldbody.add_geom()
        g.name = f"{ROCK_GEOM_PREFIX}{i:04d}"
        g.type = mujoco.mjtGeom.mjGEOM_ELLIPSOID
        g.pos, g.quat, g.size = pos, quat, size
        g.material = "rock"
        g.contype, g.conaffinity, g.condim = 0, 1, 3
        g.friction = [0.8, 0.02, 0.001]
        g.group = 0


def compile_world(spec: mujoco.MjSpec) -> mujoco.MjModel:
    model = spec.compile()
    return model
