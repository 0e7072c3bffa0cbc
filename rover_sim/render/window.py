"""Streamed terrain: move a compiled render model to the physics window's new place without recompiling it.

Every window of a streamed site has the same grid, so the render model's tile meshes, terrain texture and rock
slots keep their layout from one window to the next; only their contents change. Rebuilding the render model
for each window (a spec copy, ~1100 tile meshes, a compile and a new GL context per renderer) cost about 3 s per
re-centre, a re-centre every 5-8 m of autonav. :func:`follow_window` instead writes the new window's tile
meshes (:func:`rover_sim.render.tiles.write_tile_meshes`), its painted texture and its rocks into the same model
and uploads them to the existing GL contexts (``mjr_uploadMesh`` / ``mjr_uploadTexture``), as the rut
re-meshing of :mod:`rover_sim.render.ruts` does for deformed tiles.

The geometry drawn is the same as a fresh build's up to float32 rounding of the vertices (they are stored in the
first window's mesh frames instead of each new window's), about a micrometre. Measured on a spirit_plains_sol
window (hazcam, 256 px RGB): 10 % of the pixels differ from a freshly built model's, almost all by one grey level
(texture sampling at the rounding's scale); about 0.1 % by more, along far silhouettes where an edge crosses a
pixel centre. ``tests/rover_sim/test_render_window.py`` bounds both.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import mujoco
import numpy as np

from rover_sim.render.render_world import ROCK_MATERIAL, rock_rgba, slot_box
from rover_sim.render.tiles import GROUP_HIDDEN, GROUP_SHOWN, tile_meshes, write_tile_meshes
from rover_sim.sim.assembly import ROCK_GEOM_PREFIX

if TYPE_CHECKING:
    from rover_sim.render.render_world import RenderWorld


def follow_window(world: RenderWorld, contexts: list[mujoco.Renderer], texture_rgb: np.ndarray | None) -> bool:
    """Move ``world`` (a render model of a streamed site) to its simulation's current window, in place, and upload
    the changes to ``contexts``. ``texture_rgb`` is the new window's painted terrain texture (None: unpainted).
    Returns False, having changed nothing, when the layout differs (then build a new :class:`RenderWorld`)."""
    sim, m, cfg = world.sim, world.model, world.config
    terrain = sim.terrain
    tex_id = m.texture("terrain_albedo").id if texture_rgb is not None else -1
    if tex_id >= 0 and texture_rgb.shape != (int(m.tex_height[tex_id]), int(m.tex_width[tex_id]), 3):
        return False
    tiles, meshes = tile_meshes(terrain, cfg.terrain_tile_m, cfg.max_terrain_tiles)
    if tiles.geom_names.shape != world.tiles.geom_names.shape or not write_tile_meshes(m, meshes):
        return False
    if tex_id >= 0:
        adr, n = int(m.tex_adr[tex_id]), texture_rgb.size
        m.tex_data[adr : adr + n] = np.ascontiguousarray(texture_rgb[::-1], dtype=np.uint8).ravel()
    sim.streamer.apply(m, terrain)  # rock slots (and the hidden hfield: never drawn, so never uploaded)
    rock_mat = m.material(ROCK_MATERIAL).id
    slots = [m.geom(f"{ROCK_GEOM_PREFIX}{i:04d}").id for i in range(sim.streamer.rock_slots)]
    for k, gid in enumerate(slots):
        if k < len(terrain.rocks):
            m.geom_matid[gid], m.geom_rgba[gid] = rock_mat, rock_rgba(terrain.rocks[k], terrain.seed)
        else:
            m.geom_group[gid] = GROUP_HIDDEN  # a parked slot (below the window): never drawn
    world.rock_ids = np.array(slots[: len(terrain.rocks)], dtype=np.int32)
    m.geom_group[world.rock_ids] = GROUP_SHOWN
    world.rock_boxes = np.asarray([slot_box(r) for r in terrain.rocks]).reshape(-1, 2, 3)
    world.tiles, world.floor_z = tiles, float(terrain.heights_m.min())
    world.terrain_version = sim.terrain_version
    mesh_ids = [m.mesh(tm.name).id for tm in meshes]
    for r in contexts:
        with r._gl_context.as_current():
            for mid in mesh_ids:
                mujoco.mjr_uploadMesh(m, r._mjr_context, mid)
            if tex_id >= 0:
                mujoco.mjr_uploadTexture(m, r._mjr_context, tex_id)
    return True
