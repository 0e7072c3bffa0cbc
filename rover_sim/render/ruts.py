"""Ruts in the render model: re-mesh the terrain tiles where the deformable terrain changed.

The render model draws the ground as tile meshes (:mod:`rover_sim.render.tiles`), built once from the initial
heights. With deformation on (``[physics] deformable = true``, :mod:`rover_sim.sim.deform`) the physics heightfield
changes under the wheels; before a render, :meth:`TileRuts.refresh` moves the vertices of every tile level that
covers a changed cell by the height change at its grid node (grid and skirt alike), recomputes their normals (so
the ruts shade), and uploads the meshes to the live GL contexts. Throttled: at most once per ``every_m`` of rover
travel, so a render every step does not re-mesh every step.

A deformed tile is drawn at its exact level from then on (its coarser levels' height errors no longer describe
it): its row of ``tiles.error_m`` is set to infinity beyond level 0.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import mujoco
import numpy as np

if TYPE_CHECKING:
    from rover_sim.render.tiles import TerrainTiles
    from rover_sim.sim.physics import RoverSim

RUT_REFRESH_M = 0.05  # rover travel between re-meshes (a little more than one 4 cm cell)


def quat_to_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat_wxyz, dtype=float))
    return mat.reshape(3, 3)


class TileRuts:
    """Keeps the render model's tile meshes of ``sim`` in step with its deformable terrain."""

    def __init__(self, model: mujoco.MjModel, tiles: TerrainTiles, sim: RoverSim, every_m: float = RUT_REFRESH_M):
        self.model, self.tiles, self.sim, self.every_m = model, tiles, sim, every_m
        t = sim.terrain
        self._cell, self._x0, self._y0 = t.cell_size_m, -t.half_x_m, -t.half_y_m
        self._shown: np.ndarray | None = None  # the heights the tile meshes show (copied once deformation is on)
        self._ids = tiles.geom_ids(model)
        self._last_xy: np.ndarray | None = None
        self._pending: tuple[int, int, int, int] | None = None
        self.remeshed_tiles = 0  # tiles re-meshed so far (diagnostics)

    def refresh(self, contexts: list[mujoco.Renderer]) -> int:
        """Re-mesh the tiles over cells changed since the last refresh (if the rover moved ``every_m``); upload
        them to ``contexts``. Returns the number of tiles re-meshed."""
        deform = self.sim.deform
        if deform is None:
            return 0
        if self._shown is None:
            self._shown = np.asarray(self.sim.terrain.heights_m, dtype=float).copy()
        box = deform.pop_dirty_cells()
        if box is not None:
            p = self._pending
            self._pending = box if p is None else (min(p[0], box[0]), max(p[1], box[1]), min(p[2], box[2]),
                                                   max(p[3], box[3]))  # fmt: skip
        xy = self.sim.position_m()[:2]
        if self._pending is None or (self._last_xy is not None and np.hypot(*(xy - self._last_xy)) < self.every_m):
            return 0
        self._last_xy = xy.copy()
        i0, i1, j0, j1 = self._pending
        self._pending = None
        # one cell of margin: the normals of the nodes next to a change change too
        i0, j0 = max(i0 - 1, 0), max(j0 - 1, 0)
        i1, j1 = min(i1 + 1, self._shown.shape[0] - 1), min(j1 + 1, self._shown.shape[1] - 1)
        new = deform.heights_box_m(i0, i1, j0, j1)
        delta = new - self._shown[i0 : i1 + 1, j0 : j1 + 1]
        self._shown[i0 : i1 + 1, j0 : j1 + 1] = new
        lo = np.array([self._x0 + (j0 - 1) * self._cell, self._y0 + (i0 - 1) * self._cell])
        hi = np.array([self._x0 + (j1 + 1) * self._cell, self._y0 + (i1 + 1) * self._cell])
        b = self.tiles.boxes
        hit = np.flatnonzero(np.all(b[:, 0, :2] <= hi, axis=1) & np.all(b[:, 1, :2] >= lo, axis=1))
        meshes = []
        for t in hit:
            for g in self._ids[t]:
                if g >= 0:
                    meshes.append(self._remesh(int(g), i0, j0, delta))
            self.tiles.error_m[t, 1:] = np.inf  # draw the deformed tile exactly
        for r in contexts:
            with r._gl_context.as_current():
                for mid in meshes:
                    mujoco.mjr_uploadMesh(self.model, r._mjr_context, mid)
        self.remeshed_tiles += len(hit)
        return len(hit)

    def _remesh(self, geom_id: int, i0: int, j0: int, delta: np.ndarray) -> int:
        """Move one tile mesh's vertices by the height change ``delta`` (cells from ``(i0, j0)``) at their grid
        nodes; new normals. Returns the mesh id."""
        m = self.model
        mid = int(m.geom_dataid[geom_id])
        va, vn = int(m.mesh_vertadr[mid]), int(m.mesh_vertnum[mid])
        R, p = quat_to_matrix(m.geom_quat[geom_id]), m.geom_pos[geom_id]
        world = m.mesh_vert[va : va + vn] @ R.T + p
        j = np.clip(np.rint((world[:, 0] - self._x0) / self._cell).astype(int), 0, self._shown.shape[1] - 1)
        i = np.clip(np.rint((world[:, 1] - self._y0) / self._cell).astype(int), 0, self._shown.shape[0] - 1)
        di, dj = i - i0, j - j0
        inside = (di >= 0) & (di < delta.shape[0]) & (dj >= 0) & (dj < delta.shape[1])
        world[inside, 2] += delta[di[inside], dj[inside]]
        m.mesh_vert[va : va + vn] = (world - p) @ R
        h, c = self._shown, self._cell
        jl, jr = np.maximum(j - 1, 0), np.minimum(j + 1, h.shape[1] - 1)
        il, ir = np.maximum(i - 1, 0), np.minimum(i + 1, h.shape[0] - 1)
        gx = (h[i, jr] - h[i, jl]) / ((jr - jl) * c)
        gy = (h[ir, j] - h[il, j]) / ((ir - il) * c)
        n = np.stack([-gx, -gy, np.ones_like(gx)], axis=1)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        na, nn = int(m.mesh_normaladr[mid]), int(m.mesh_normalnum[mid])
        if nn == vn:  # one normal per vertex (as the tiles are built)
            m.mesh_normal[na : na + nn] = n @ R
        return mid
