"""Deformable terrain (SCM-class) under the wheels: ruts written into the MuJoCo heightfield, berms, multipass.

The wheel–soil law gives each wheel's sinkage below the undisturbed surface ``z`` (Bekker + slip-sinkage). Here
that sinkage becomes geometry, as in Chrono's SCM but on MuJoCo's heightfield grid:

* **ruts**: every deformable cell under a wheel's contact patch (a ``width x (contact length + one cell)``
  rectangle along the wheel's heading) is lowered to ``h0 - z`` (``h0`` the undisturbed height), never raised by a
  wheel; physics sees it at once (``model.hfield_data``), so the rover rides in its ruts;
* **rut walls**: the rut's floor is the tread's width (the collision wheel is the true 0.16 m cylinder on its
  ground plate, :mod:`rover_sim.sim.ground_plates`, which feels the ground under the tread only: the same cells a
  rut floor is written into, so the wheel sits in its rut at the law's sinkage); beside it the walls rise at the
  soil's angle of repose (``REPOSE_DEG``, loose sand 30-35 deg) to the undisturbed surface, as loose soil
  slumps into a rut's sides;
* **berms**: the soil a wheel pushes down is put back beside the rut (the cells from the walls' top out to
  ``max(BERM_CELLS cells, BERM_SPREAD z)`` beyond, equally, constants of :mod:`rover_sim.sim.wr_kernel`; wider
  beside a deeper rut, so a wheel digging in spreads the soil outward: its crest stays about as low as the rut is
  deep, up to 1.24x where wheels dig in as they start, tests/rover_sim/test_purgatory.py): volume is conserved to
  the grid's resolution;
* **multipass / compaction**: a rut is plastic: a later wheel deepens it only where its own sinkage is larger
  (SCM's loading-only-beyond-the-previous-maximum); the law is told the rut depth ahead of each wheel
  (``law.presink_m``), so only the new compaction resists (a second pass sinks less and rolls easier);
* **no change** on bedrock, mixed-on-rock cells marked non-deformable, or when the wheel is on a rock.

Updates are throttled: a wheel writes when its contact has moved ``UPDATE_M`` or its sinkage grew 1 mm since its
last write, so the per-step cost is a distance check per wheel (see ``rover-sim bench slip``'s speed rows). The
per-step arithmetic and the rut writes are compiled (:func:`rover_sim.sim.wr_kernel.deform_after_law`); the cells
a rut changes are written straight into ``model.hfield_data``, which is what MuJoCo's collision reads (nothing is
uploaded per step: a heightfield upload, ``mjr_uploadHField``, is render-side only and the render model draws tiles).

Rendering: the render model draws LOD tile meshes, not the physics heightfield (``rover_sim.render.tiles``); the
cells changed since the last render (:meth:`DeformableTerrain.pop_dirty_cells`) are re-meshed into those tiles by
``rover_sim.render.ruts`` before each render, so the cameras see the ruts.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Protocol

import numpy as np

from nav.types import WHEELS
from rover_sim.sim.wr_kernel import (
    P_ALPHA,
    P_BASE,
    P_CELL,
    P_SCALE,
    P_WALL_TAN,
    P_WIDTH,
    P_X0,
    P_Y0,
    deform_after_law,
)

if TYPE_CHECKING:
    import mujoco

    from rover_sim.sim.terramechanics_wr import WheelSoilLaw
    from terrains import Terrain

SINK_FILTER_S = 0.5
REPOSE_DEG = 33.0  # slope of a rut's walls: loose sand's angle of repose, 30-35 deg (Mars: Atwood-Genco et al. 2015)
_RENDER, _LOG = 0, 1  # rows of the dirty-cell boxes: one per consumer


class DeformingSim(Protocol):
    """What the deformable ground reads of the physics that owns it (:class:`rover_sim.sim.physics.RoverSim`): the
    compiled model and its data, the terrain, the Wong-Reece law and the physics step."""

    model: mujoco.MjModel
    data: mujoco.MjData
    terrain: Terrain
    law: WheelSoilLaw

    @property
    def timestep_s(self) -> float: ...


class DeformableTerrain:
    """The heightfield of ``sim`` made deformable; ``heights_m()`` is the current surface (same grid as the terrain)."""

    def __init__(self, sim: DeformingSim, deformable_materials: tuple[bool, ...]) -> None:
        m, t = sim.model, sim.terrain
        self.model = m
        hid = m.hfield("terrain").id
        self._adr = int(m.hfield_adr[hid])
        self._nrow, self._ncol = int(m.hfield_nrow[hid]), int(m.hfield_ncol[hid])
        self._cell = t.cell_size_m
        self._x0, self._y0 = -t.half_x_m, -t.half_y_m
        h0 = np.asarray(t.heights_m, dtype=float)
        self.heights_before_m = h0.copy()
        self._h0 = h0.copy()
        self._h = h0.copy()
        mats = np.asarray(t.materials, dtype=int)
        self._soft = np.ascontiguousarray(np.asarray(deformable_materials, dtype=bool)[mats])
        self._soft_material = np.asarray(deformable_materials, dtype=bool)
        self._hf = m.hfield_data
        self._last = np.tile([np.inf, np.inf, 0.0], (6, 1))  # contact x, y and sinkage at each wheel's last write
        self._zf = np.zeros(6)  # sinkage low-passed over SINK_FILTER_S (load spikes of vibration do not dig)
        params = np.zeros(8)  # wr_kernel.P_* entries
        params[P_CELL], params[P_X0], params[P_Y0] = self._cell, self._x0, self._y0
        params[P_BASE] = float(m.geom("terrain").pos[2])
        params[P_SCALE] = float(m.hfield_size[hid][2])  # elevation range
        params[P_ALPHA] = sim.timestep_s / (SINK_FILTER_S + sim.timestep_s)
        params[P_WIDTH] = sim.law.width_m
        params[P_WALL_TAN] = math.tan(math.radians(REPOSE_DEG))
        self._params = params
        self.enabled = True
        # (valid, i0, i1, j0, j1) cells changed since pop_dirty_cells (row _RENDER) / pop_dirty_cells_for_log (_LOG)
        self._dirty = np.zeros((2, 5), dtype=np.int64)
        self._xpos = sim.data.xpos  # body positions (a live view): the wheel centres
        self._wheel_ids = np.array([m.body(f"wheel_{w}").id for w in WHEELS], dtype=np.int64)

    # ------------------------------------------------------------------ state
    def heights_m(self) -> np.ndarray:
        return self._h.copy()

    def rut_depth_at(self, x: float, y: float) -> float:
        """Depth of the surface below the undisturbed ground at (x, y) (nearest cell), m (negative on a berm)."""
        i, j = self._cell_of(x, y)
        return float(self._h0[i, j] - self._h[i, j])

    def heights_box_m(self, i0: int, i1: int, j0: int, j1: int) -> np.ndarray:
        """Current heights of rows ``i0..i1`` and columns ``j0..j1`` (inclusive), m."""
        return self._h[i0 : i1 + 1, j0 : j1 + 1].copy()

    def pop_dirty_cells(self) -> tuple[int, int, int, int] | None:
        """Inclusive cell box ``(i0, i1, j0, j1)`` holding every cell changed since the last call (None: none);
        for one consumer (the render model's tiles, ``rover_sim.render.ruts``)."""
        return self._pop(_RENDER)

    def pop_dirty_cells_for_log(self) -> tuple[int, int, int, int] | None:
        """As :meth:`pop_dirty_cells`, for a second consumer with its own box (the recording's ground tiles,
        ``rover_sim.io.rut_log``)."""
        return self._pop(_LOG)

    def _pop(self, row: int) -> tuple[int, int, int, int] | None:
        d = self._dirty[row]
        if not d[0]:
            return None
        box = (int(d[1]), int(d[2]), int(d[3]), int(d[4]))
        d[:] = 0
        return box

    def _cell_of(self, x: float, y: float) -> tuple[int, int]:
        j = min(max(int((x - self._x0) / self._cell + 0.5), 0), self._ncol - 1)
        i = min(max(int((y - self._y0) / self._cell + 0.5), 0), self._nrow - 1)
        return i, j

    # ------------------------------------------------------------------ per physics step
    def after_law(self, sim: DeformingSim, sd: np.ndarray, mats: np.ndarray) -> None:
        """Called by RoverSim after the soil law each step (``sd`` its sensor block, ``mats`` the material under
        each wheel): presink for the law, ruts where a wheel has moved (compiled: wr_kernel.deform_after_law)."""
        if not self.enabled:
            return
        law = sim.law
        deform_after_law(sd, mats, self._soft_material, law.out_state(), law.state_arrays(), law.axles, self._xpos,
                         self._wheel_ids, self._h, self._h0, self._soft, self._hf, self._adr, self._params,
                         self._zf, self._last, self._dirty)  # fmt: skip
