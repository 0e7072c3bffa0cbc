"""The recording's ground in deformable runs: tiles re-logged where the wheels change them.

A rigid site logs its ground once, static (``world/terrain``, decimated to ``terrain_mesh_step``). With
``[physics] deformable = true`` (:mod:`rover_sim.sim.deform`) that one static mesh would hide the ruts, so the
ground is logged instead as ``tile_m`` square tiles on the ``sim_time`` timeline (``world/terrain/ground/t<i>_<j>``):
every tile at the start, at the static mesh's decimation, then each tile holding cells the wheels changed again, at
full resolution (the 4 cm cells: a 16 cm wide rut spans four of them). Throttled: the changed tiles wait until the
rover has moved ``every_m`` or ``every_s`` of sim time has passed (a rover digging in place) since the last update;
:meth:`RutLog.flush` logs what is still waiting at the end of the run. The changed cells come from
:meth:`DeformableTerrain.pop_dirty_cells_for_log`, a box of its own (the render model's ``rover_sim.render.ruts``
consumes the other).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from rover_sim.io.recording_helpers import terrain_mesh_step
from terrains import Terrain

if TYPE_CHECKING:
    from rover_sim.io.recorder_protocol import Recorder
    from rover_sim.sim.physics import RoverSim

TILE_M = 1.0  # ground tile side in the recording
EVERY_M = 0.5  # rover travel between updates of the changed tiles
EVERY_S = 20.0  # ... or sim time (a rover digging in without moving)


class RutLog:
    """Logs the ground of ``sim`` (deformation on) to ``rec`` as tiles, re-logging the ones the wheels changed."""

    def __init__(
        self, sim: RoverSim, rec: Recorder, tile_m: float = TILE_M, every_m: float = EVERY_M, every_s: float = EVERY_S
    ) -> None:
        if sim.deform is None:
            raise ValueError("RutLog needs a deformable terrain ([physics] deformable = true)")
        if not (tile_m > 0.0 and every_m >= 0.0 and every_s >= 0.0):
            raise ValueError(
                f"RutLog: tile_m must be > 0, every_m and every_s >= 0; got {tile_m}, {every_m}, {every_s}"
            )
        self.sim, self.rec, self.every_m, self.every_s = sim, rec, every_m, every_s
        t = sim.terrain
        self._cell, self._x0, self._y0 = t.cell_size_m, -t.half_x_m, -t.half_y_m
        self._materials = np.asarray(t.materials)
        self._nrow, self._ncol = t.nrow, t.ncol
        self.tile_cells = max(1, round(tile_m / t.cell_size_m))
        self._ntr = math.ceil((self._nrow - 1) / self.tile_cells)
        self._ntc = math.ceil((self._ncol - 1) / self.tile_cells)
        self.coarse_step = terrain_mesh_step(t.nrow, t.ncol)
        self._pending: set[tuple[int, int]] = set()
        self._last_xy = np.asarray(sim.position_m()[:2], dtype=float)
        self._last_t_s = sim.time_s
        self.updates = 0  # throttled updates that logged tiles
        self.tiles_relogged = 0  # tile meshes re-logged after a change

    def log_all(self, t_s: float, step: int | None) -> None:
        """Every tile, at the static mesh's decimation (the start of the run)."""
        for a in range(self._ntr):
            for b in range(self._ntc):
                self._log_tile(a, b, t_s, step, self.coarse_step)
        self._last_t_s = t_s

    def update(self, t_s: float, step: int | None) -> int:
        """Collect changed cells; if the rover moved ``every_m`` (or ``every_s`` passed) since the last update,
        re-log their tiles at full resolution. Returns the number of tiles logged."""
        self._collect()
        if not self._pending:
            return 0
        xy = np.asarray(self.sim.position_m()[:2], dtype=float)
        if math.hypot(*(xy - self._last_xy)) < self.every_m and t_s - self._last_t_s < self.every_s:
            return 0
        self._last_xy = xy
        return self.flush(t_s, step)

    def flush(self, t_s: float, step: int | None) -> int:
        """Re-log every tile changed and not logged yet, now (unthrottled). Returns the number of tiles."""
        self._collect()
        tiles, self._pending = sorted(self._pending), set()
        for a, b in tiles:
            self._log_tile(a, b, t_s, step, 1)
        self._last_t_s = t_s
        self.updates += bool(tiles)
        self.tiles_relogged += len(tiles)
        return len(tiles)

    def tile_of_cell(self, i: int, j: int) -> tuple[int, int]:
        """The tile ``(a, b)`` holding cell row ``i``, column ``j`` (a cell on a shared edge: the lower tile)."""
        n = self.tile_cells
        return min(i // n, self._ntr - 1), min(j // n, self._ntc - 1)

    def _collect(self) -> None:
        box = self.sim.deform.pop_dirty_cells_for_log()  # type: ignore[union-attr]
        if box is None:
            return
        i0, i1, j0, j1 = box
        n = self.tile_cells
        # a cell on a tile edge belongs to both tiles beside it
        for a in range(max((i0 - 1) // n, 0), min(i1 // n, self._ntr - 1) + 1):
            for b in range(max((j0 - 1) // n, 0), min(j1 // n, self._ntc - 1) + 1):
                self._pending.add((a, b))

    def _log_tile(self, a: int, b: int, t_s: float, step: int | None, mesh_step: int) -> None:
        n = self.tile_cells
        r0, c0 = a * n, b * n
        r1, c1 = min(r0 + n, self._nrow - 1), min(c0 + n, self._ncol - 1)
        heights = self.sim.deform.heights_box_m(r0, r1, c0, c1)  # type: ignore[union-attr]
        tile = Terrain(heights_m=heights, cell_size_m=self._cell, materials=self._materials[r0 : r1 + 1, c0 : c1 + 1])
        centre = (self._x0 + 0.5 * (c0 + c1) * self._cell, self._y0 + 0.5 * (r0 + r1) * self._cell)
        self.rec.log_ground_tile(f"t{a}_{b}", t_s, step, tile, centre, mesh_step)
