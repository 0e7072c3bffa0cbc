"""Deformable terrain (SCM-class) under the wheels: ruts written into the MuJoCo heightfield, berms, multipass.

The wheel–soil law gives each wheel's sinkage below the undisturbed surface ``z`` (Bekker + slip-sinkage). Here
that sinkage becomes geometry, as in Chrono's SCM but on MuJoCo's heightfield grid:

* **ruts**: every deformable cell under a wheel's contact patch (a ``width x (contact length + one cell)``
  rectangle along the wheel's heading) is lowered to ``h0 - z`` (``h0`` the undisturbed height), never raised by a
  wheel; physics sees it at once (``model.hfield_data``), so the rover rides in its ruts;
* **rut shoulders**: the collision wheel is a sphere of the wheel's radius ``r``, wider than the 16 cm tread: the
  cells beside the tread out to ``r`` are lowered to the sphere's underside at the rut depth
  (``h0 - z + r - sqrt(r^2 - d^2)`` at ``d`` from the wheel's mid-plane), so the wheel sits in its rut at the law's
  sinkage instead of hanging on the rut's edges;
* **berms**: the soil a wheel pushes down is put back beside the rut (the cells from the wider of half a width and
  ``r`` out to ``max(BERM_CELLS cells, BERM_SPREAD z)`` beyond, equally; never under the collision sphere, where a
  berm raised in one write would push into it; wider beside a deeper rut, so a wheel digging in spreads the soil
  outward: its berm's crest, next to the rut, stays below the rut's depth): volume is conserved to the grid's
  resolution;
* **multipass / compaction**: a rut is plastic: a later wheel deepens it only where its own sinkage is larger
  (SCM's loading-only-beyond-the-previous-maximum); the law is told the rut depth ahead of each wheel
  (``law.presink_m``), so only the new compaction resists (a second pass sinks less and rolls easier);
* **no change** on bedrock, mixed-on-rock cells marked non-deformable, or when the wheel is on a rock.

Updates are throttled: a wheel writes when its contact has moved ``UPDATE_M`` or its sinkage grew 1 mm since its
last write, so the per-step cost is a distance check per wheel (see ``rover-sim bench slip``'s speed rows).

Rendering: the render model draws LOD tile meshes, not the physics heightfield (``rover_sim.render.tiles``); the
cells changed since the last render (:meth:`DeformableTerrain.pop_dirty_cells`) are re-meshed into those tiles by
``rover_sim.render.ruts`` before each render, so the cameras see the ruts.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from nav.types import WHEELS

if TYPE_CHECKING:
    from rover_sim.sim.physics import RoverSim

UPDATE_M = 0.02  # contact travel between rut writes (half a 4 cm cell)
BERM_CELLS = 2
BERM_SPREAD = 3.0  # a berm is at least this many rut depths wide (about a third of the rut's depth tall)
SINK_FILTER_S = 0.5


class DeformableTerrain:
    """The heightfield of ``sim`` made deformable; ``heights_m()`` is the current surface (same grid as the terrain)."""

    def __init__(self, sim: RoverSim, deformable_materials: tuple[bool, ...]) -> None:
        m, t = sim.model, sim.terrain
        self.model = m
        hid = m.hfield("terrain").id
        self._adr = int(m.hfield_adr[hid])
        self._nrow, self._ncol = int(m.hfield_nrow[hid]), int(m.hfield_ncol[hid])
        self._scale = float(m.hfield_size[hid][2])  # elevation range
        self._base = float(m.geom("terrain").pos[2])
        self._cell = t.cell_size_m
        self._x0, self._y0 = -t.half_x_m, -t.half_y_m
        h0 = np.asarray(t.heights_m, dtype=float)
        self.heights_before_m = h0.copy()
        self._h0 = h0.tolist()
        self._h = h0.tolist()
        mats = np.asarray(t.materials, dtype=int)
        self._soft = np.asarray(deformable_materials, dtype=bool)[mats].tolist()
        self._hf = m.hfield_data
        self._last = [(math.inf, math.inf, 0.0)] * 6  # contact x, y and sinkage at each wheel's last write
        self._zf = [0.0] * 6  # sinkage low-passed over SINK_FILTER_S (load spikes of vibration do not dig)
        self._alpha = sim.timestep_s / (SINK_FILTER_S + sim.timestep_s)
        self.enabled = True
        self._dirty: tuple[int, int, int, int] | None = None  # (i0, i1, j0, j1) cells changed since pop_dirty_cells
        self._dirty_log: tuple[int, int, int, int] | None = None  # the same, since pop_dirty_cells_for_log
        self._sphere_r = sim.law.radius_m  # the collision wheel: a sphere of the wheel's radius (models/mer/rover.xml)
        self._xpos = sim.data.xpos  # body positions (a live view): the wheel centres
        self._wheel_ids = [m.body(f"wheel_{w}").id for w in WHEELS]

    # ------------------------------------------------------------------ state
    def heights_m(self) -> np.ndarray:
        return np.array(self._h)

    def rut_depth_at(self, x: float, y: float) -> float:
        """Depth of the surface below the undisturbed ground at (x, y) (nearest cell), m (negative on a berm)."""
        i, j = self._cell_of(x, y)
        return self._h0[i][j] - self._h[i][j]

    def heights_box_m(self, i0: int, i1: int, j0: int, j1: int) -> np.ndarray:
        """Current heights of rows ``i0..i1`` and columns ``j0..j1`` (inclusive), m."""
        return np.array([row[j0 : j1 + 1] for row in self._h[i0 : i1 + 1]])

    def pop_dirty_cells(self) -> tuple[int, int, int, int] | None:
        """Inclusive cell box ``(i0, i1, j0, j1)`` holding every cell changed since the last call (None: none);
        for one consumer (the render model's tiles, ``rover_sim.render.ruts``)."""
        box, self._dirty = self._dirty, None
        return box

    def pop_dirty_cells_for_log(self) -> tuple[int, int, int, int] | None:
        """As :meth:`pop_dirty_cells`, for a second consumer with its own box (the recording's ground tiles,
        ``rover_sim.mission.rut_log``)."""
        box, self._dirty_log = self._dirty_log, None
        return box

    def _cell_of(self, x: float, y: float) -> tuple[int, int]:
        j = min(max(int((x - self._x0) / self._cell + 0.5), 0), self._ncol - 1)
        i = min(max(int((y - self._y0) / self._cell + 0.5), 0), self._nrow - 1)
        return i, j

    # ------------------------------------------------------------------ per physics step
    def after_law(self, sim: RoverSim, pos: list[tuple[float, float, float]], mats: list[int]) -> None:
        """Called by RoverSim after the soil law each step: presink for the law, ruts where a wheel has moved."""
        if not self.enabled:
            return
        law = sim.law
        st = law.out_state()
        W, z_all = st[0], st[1]
        axles = law.axles
        centres = self._xpos[self._wheel_ids].tolist()
        for w in range(6):
            if W[w] <= 0.0 or not law.materials[mats[w]].deformable:
                law.presink_m[w] = self._zf[w] = 0.0
                continue
            ax, ay, _ = axles[w]
            hx, hy = ay, -ax  # heading = axle x up, projected
            hn = math.hypot(hx, hy) or 1.0
            hx, hy = hx / hn, hy / hn
            # the rut lies in the wheel's mid-plane: the contact point's offset from the wheel centre along the
            # heading is kept (on a slope the wheel touches ahead of or behind its axle), the sideways one dropped
            # (a wheel deep in its rut also touches the rut's side: that point is not where the tread is)
            cx, cy, _ = centres[w]
            along = (pos[w][0] - cx) * hx + (pos[w][1] - cy) * hy
            px, py = cx + along * hx, cy + along * hy
            lp = law.patch_length(w)
            lead = 0.5 * lp + UPDATE_M + 2.5 * self._cell  # beyond this wheel's own footprint
            law.presink_m[w] = max(self.rut_depth_at(px + lead * hx, py + lead * hy), 0.0)
            lx, ly, lz = self._last[w]
            z = self._zf[w] = self._zf[w] + self._alpha * (z_all[w] - self._zf[w])
            if (px - lx) ** 2 + (py - ly) ** 2 < UPDATE_M * UPDATE_M and z < lz + 0.001:
                continue
            self._last[w] = (px, py, z)
            self._write_rut(px, py, hx, hy, z, lp, law.width_m)

    def _write_rut(self, px: float, py: float, hx: float, hy: float, z: float, lp: float, width: float) -> None:
        cell = self._cell
        # behind: the patch; ahead: the patch plus the travel until the next write and a cell, so that the
        # collision sphere never meets the rut's front edge (the law already resists the motion: no double count)
        back, front, half_w = 0.5 * lp + 0.5 * cell, 0.5 * lp + UPDATE_M + 1.5 * cell, 0.5 * width
        r = self._sphere_r
        shoulder = max(half_w, r)
        reach = shoulder + max(BERM_CELLS * cell, BERM_SPREAD * z)
        span = int(math.ceil(max(front, reach) / cell)) + 1
        ci, cj = self._cell_of(px, py)
        h, h0, soft = self._h, self._h0, self._soft
        displaced = 0.0
        berm: list[tuple[int, int]] = []
        for i in range(max(ci - span, 0), min(ci + span + 1, self._nrow)):
            dy = self._y0 + i * cell - py
            row_h, row_h0, row_soft = h[i], h0[i], soft[i]
            for j in range(max(cj - span, 0), min(cj + span + 1, self._ncol)):
                if not row_soft[j]:
                    continue
                dx = self._x0 + j * cell - px
                along, across = dx * hx + dy * hy, abs(-dx * hy + dy * hx)
                if along > front or along < -back:
                    continue
                if across < shoulder:
                    target = row_h0[j] - z  # the tread; beside it, the sphere's underside
                    if across > half_w:
                        target += r - math.sqrt(r * r - across * across)
                    if target < row_h[j]:
                        displaced += row_h[j] - target
                        row_h[j] = target
                        self._push(i, j)
                elif across <= reach:
                    berm.append((i, j))
        if displaced > 0.0 and berm:
            dh = displaced / len(berm)
            for i, j in berm:
                h[i][j] += dh
                self._push(i, j)
        if displaced > 0.0:
            self._dirty = self._grown(self._dirty, ci, cj, span)
            self._dirty_log = self._grown(self._dirty_log, ci, cj, span)

    def _grown(self, d: tuple[int, int, int, int] | None, ci: int, cj: int, span: int) -> tuple[int, int, int, int]:
        d = d or (ci, ci, cj, cj)
        return (
            max(min(d[0], ci - span), 0),
            min(max(d[1], ci + span), self._nrow - 1),
            max(min(d[2], cj - span), 0),
            min(max(d[3], cj + span), self._ncol - 1),
        )

    def _push(self, i: int, j: int) -> None:
        self._hf[self._adr + i * self._ncol + j] = (self._h[i][j] - self._base) / self._scale
