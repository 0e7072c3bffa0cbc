"""Ruts in the render model (rover_sim/render/ruts.py): the terrain tiles follow the deformable terrain."""

from __future__ import annotations

import numpy as np

from rover_sim.bench.mobility import slope_terrain, wr_sim
from rover_sim.render.config import RenderConfig
from rover_sim.render.render_world import RenderWorld
from rover_sim.render.ruts import quat_to_matrix
from rover_sim.sim.drive import Straight, execute


def _tile_vertices_world(world: RenderWorld) -> np.ndarray:
    m = world.model
    out = []
    for g in world.tile_ids[:, 0]:
        mid = int(m.geom_dataid[g])
        va, vn = int(m.mesh_vertadr[mid]), int(m.mesh_vertnum[mid])
        out.append(m.mesh_vert[va : va + vn] @ quat_to_matrix(m.geom_quat[g]).T + m.geom_pos[g])
    return np.concatenate(out)


def test_tiles_show_the_ruts_after_a_drive():
    sim = wr_sim(slope_terrain("sand", 0.0, 0, size_m=(6.0, 4.0)))
    sim.place(-1.5, 0.0, 0.0)
    world = RenderWorld(sim, RenderConfig())
    before = _tile_vertices_world(world)
    execute(sim, Straight(1.0), speed_m_s=0.05)
    depth = sim.deform.heights_before_m - sim.deform.heights_m()
    assert depth.max() > 2e-3  # the drive left ruts
    assert world.ruts.refresh([]) > 0
    after = _tile_vertices_world(world)
    drop = before[:, 2] - after[:, 2]
    assert abs(drop.max() - depth.max()) < 1e-5
    assert np.allclose(before[:, :2], after[:, :2], atol=1e-5)  # only heights move
    # every grid vertex of level 0 sits on the deformed surface
    t = sim.terrain
    j = np.rint((after[:, 0] + t.half_x_m) / t.cell_size_m).astype(int)
    i = np.rint((after[:, 1] + t.half_y_m) / t.cell_size_m).astype(int)
    on_grid = np.abs(after[:, 2] - sim.deform.heights_m()[i, j]) < 1e-5
    assert on_grid.mean() > 0.8  # the rest are the skirts hanging below the tile edges
    deformed = np.isinf(world.tiles.error_m[:, 1:]).all(axis=1)
    assert 0 < deformed.sum() < len(deformed)  # re-meshed tiles are drawn exactly; the far ones keep their LOD
    # throttled: under RUT_REFRESH_M of travel since the last re-mesh, changed cells wait for the next one
    execute(sim, Straight(0.03), speed_m_s=0.05)
    assert world.ruts.refresh([]) == 0
    execute(sim, Straight(0.05), speed_m_s=0.05)
    assert world.ruts.refresh([]) > 0
