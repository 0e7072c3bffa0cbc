"""The Wong–Reece law's own wheel–ground contact: the true 0.25 m x 0.16 m wheel cylinder on a ground plate.

MuJoCo's sphere-versus-heightfield test is most of a bare physics step on the scenarios' 0.04 m
cells (it runs a convex collision against every cell prism under each of the six wheels: 72-77 of ~100 us,
measured). With ``soil_model = "wong_reece"`` the wheel–ground contact is computed here instead, from the
heightfield under the wheel's true cylinder:

* each collision wheel is a **cylinder** of the wheel's radius and width (``rover.xml``'s visual wheel), and it
  does not collide with the heightfield;
* each wheel has a **ground plate**: a mocap plane that only that wheel touches (an explicit, frictionless contact
  pair with the wheel's solver parameters). Before every physics step :func:`place_plates` puts each plate on the
  local ground under its wheel: the plate's normal is the least-squares plane of the heights at 3 x 3 points
  over the wheel's footprint (bilinear in the heightfield, so any cell size works), and its offset is the highest
  point of the ground the wheel's rim would meet: every heightfield vertex under the tread (along the wheel's
  in-plane heading within ``r`` of its centre, across it within half the width, the same cells a rut is written
  into) counts with the rim's rise ``r - sqrt(r^2 - s^2)`` at its distance ``s`` ahead of or behind the centre
  taken off. On a plane that is the plane itself; a wheel in its rut sits on the rut's floor and is not lifted by
  the unrutted ground ahead unless that is higher than the rim there; a ridge under the tread carries it;
* MuJoCo's analytic cylinder–plane contact (up to four points across the tread) supplies the normal forces, so
  the load spreads over the true width (a wheel tilted across a slope loads its downhill edge), and the soil law
  reads each wheel's net ground force from a contact sensor on its plate only;
* rocks stay MuJoCo geoms: a wheel touching a rock has its own contact with friction (Coulomb, the rock's 0.8),
  never merged with the ground's force.

The ground the plates see is ``model.hfield_data`` itself, so ruts written by the deformable terrain
(:mod:`rover_sim.sim.deform`) are felt at once. The plate offset is a property of the ground and the wheel's
position on it, not of the wheel's height, so the plates are placed from the positions of the step before (the
wheels move a quarter of a millimetre a step at 5 cm/s).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numba import njit

from nav.types import WHEELS

PLATE_PREFIX = "ground_plate_"
WHEEL_CONTYPE = 2  # collision bit of the wheel cylinders: rocks answer it (conaffinity 1|2), the heightfield not
ROCK_CONAFFINITY = 3
WHEEL_ROCK_FRICTION = (0.8, 0.02, 0.001)  # the rock's Coulomb friction (world.build_spec)
HIDDEN_GROUP = 5  # never drawn (the renderer shows groups 0-2)
# entries of the plates' float parameters
G_X0, G_Y0, G_CELL, G_BASE, G_SCALE, G_RADIUS, G_HALF_WIDTH = range(7)
_SAMPLE_ALONG = 0.3  # the normal's sample points: +-0.3 r along the heading (inside the rut written ahead of a
_SAMPLE_ACROSS = 0.5  # wheel, so a rut's end does not tilt it: the law has the compaction resistance) ...
# ... and +-0.5 half-widths across it (inside the tread)


def add_ground_plates(spec: mujoco.MjSpec, radius_m: float, width_m: float) -> None:
    """Turn ``spec``'s wheels into cylinders on ground plates (module docstring), in place."""
    wheel_geoms = [spec.geom(f"wheel_{w}") for w in WHEELS]
    solref, solimp = list(wheel_geoms[0].solref), list(wheel_geoms[0].solimp)
    for w, g in zip(WHEELS, wheel_geoms, strict=True):
        g.type = mujoco.mjtGeom.mjGEOM_CYLINDER
        g.size = [radius_m, 0.5 * width_m, 0.0]
        g.quat = [math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0]  # the cylinder's axis along the axle (body y)
        g.contype, g.conaffinity = WHEEL_CONTYPE, 0
        g.condim = 3  # with a rock; the ground pair below stays frictionless (the law supplies the shear)
        g.friction = list(WHEEL_ROCK_FRICTION)
        body = spec.worldbody.add_body()
        body.name, body.mocap = f"{PLATE_PREFIX}{w}", True
        plate = body.add_geom()
        plate.name = f"{PLATE_PREFIX}{w}"
        plate.type = mujoco.mjtGeom.mjGEOM_PLANE
        plate.size = [0.3, 0.3, 0.05]
        plate.contype = plate.conaffinity = 0
        plate.group, plate.rgba = HIDDEN_GROUP, [0.0, 0.0, 0.0, 0.0]
        pair = spec.add_pair()
        pair.name = f"wheel_{w}_ground"
        pair.geomname1, pair.geomname2 = f"wheel_{w}", plate.name
        pair.condim, pair.friction = 1, [0.0, 0.0, 0.0, 0.0, 0.0]
        pair.solref, pair.solimp = solref, solimp
        sensor = spec.sensor(f"wheel_{w}_contact")
        sensor.reftype, sensor.refname = mujoco.mjtObj.mjOBJ_GEOM, plate.name
    for g in spec.geoms:
        if g.name.startswith("rock_"):
            g.conaffinity = ROCK_CONAFFINITY


class GroundPlates:
    """Places the six ground plates of a model built with :func:`add_ground_plates` (call :meth:`place` before
    each physics step; :meth:`set_terrain` after the heightfield's window or encoding changes)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, radius_m: float, width_m: float) -> None:
        self.model, self.data = model, data
        # ints: wheel body ids (6), plate mocap ids (6), heightfield address, rows, columns (one array: each array
        # argument of a compiled call costs dispatch time, and this runs every step)
        self._ints = np.zeros(15, dtype=np.int64)
        self._ints[:6] = [model.body(f"wheel_{w}").id for w in WHEELS]
        self._ints[6:12] = [model.body_mocapid[model.body(f"{PLATE_PREFIX}{w}").id] for w in WHEELS]
        # live views into MjModel / MjData (valid for their lifetime)
        self._xpos, self._xmat, self._hf = data.xpos, data.xmat, model.hfield_data
        self._mocap_pos, self._mocap_quat = data.mocap_pos, data.mocap_quat
        self._params = np.zeros(7)
        self._params[G_RADIUS], self._params[G_HALF_WIDTH] = radius_m, 0.5 * width_m
        self.set_terrain()

    def set_terrain(self) -> None:
        m = self.model
        hid = m.hfield("terrain").id
        gid = m.geom("terrain").id
        self._ints[12:15] = m.hfield_adr[hid], m.hfield_nrow[hid], m.hfield_ncol[hid]
        half_x, half_y, scale, _ = m.hfield_size[hid]
        p = self._params
        p[G_X0], p[G_Y0] = m.geom_pos[gid][0] - half_x, m.geom_pos[gid][1] - half_y
        p[G_CELL] = 2.0 * half_x / (int(m.hfield_ncol[hid]) - 1)
        p[G_BASE], p[G_SCALE] = m.geom_pos[gid][2], scale

    def place(self) -> None:
        place_plates(self._xpos, self._xmat, self._hf, self._ints, self._params, self._mocap_pos, self._mocap_quat)


@njit(cache=True)
def _height(hf: np.ndarray, adr: int, nrow: int, ncol: int, p: np.ndarray, x: float, y: float) -> float:
    """Bilinear height of the heightfield at (x, y), clamped to the grid."""
    u = min(max((x - p[G_X0]) / p[G_CELL], 0.0), ncol - 1.000001)
    v = min(max((y - p[G_Y0]) / p[G_CELL], 0.0), nrow - 1.000001)
    j, i = int(u), int(v)
    fu, fv = u - j, v - i
    k = adr + i * ncol + j
    h = (hf[k] * (1.0 - fu) + hf[k + 1] * fu) * (1.0 - fv) + (hf[k + ncol] * (1.0 - fu) + hf[k + ncol + 1] * fu) * fv
    return p[G_BASE] + p[G_SCALE] * h


@njit(cache=True)
def place_plates(xpos: np.ndarray, xmat: np.ndarray, hf: np.ndarray, ints: np.ndarray, p: np.ndarray,
                 mocap_pos: np.ndarray, mocap_quat: np.ndarray) -> None:  # fmt: skip
    """Each wheel's ground plate (module docstring): normal from a least-squares plane over the footprint, offset
    from the highest ground the rim meets; written into ``mocap_pos`` / ``mocap_quat``. ``ints``: the six wheel
    body ids, the six plates' mocap ids, then the heightfield's address in ``hf``, its rows and columns."""
    r, hw, cell = p[G_RADIUS], p[G_HALF_WIDTH], p[G_CELL]
    adr, nrow, ncol = ints[12], ints[13], ints[14]
    for w in range(6):
        b = ints[w]
        cx, cy, cz = xpos[b, 0], xpos[b, 1], xpos[b, 2]
        ax, ay = xmat[b, 1], xmat[b, 4]  # the axle: the wheel body's y axis (its spin axis)
        fx, fy = ay, -ax  # horizontal heading = axle x up
        fn = math.sqrt(fx * fx + fy * fy)
        if fn < 1e-9:
            fx, fy, fn = 1.0, 0.0, 1.0
        fx, fy = fx / fn, fy / fn
        lx, ly = -fy, fx
        # least-squares plane z = h0 + gs s + gt t over 3 x 3 points (s along, t across the heading)
        sum_ss = sum_tt = 0.0
        sum_h = sum_hs = sum_ht = 0.0
        for a in range(-1, 2):
            s = a * _SAMPLE_ALONG * r
            for c in range(-1, 2):
                t = c * _SAMPLE_ACROSS * hw
                h = _height(hf, adr, nrow, ncol, p, cx + s * fx + t * lx, cy + s * fy + t * ly)
                sum_h += h
                sum_hs += h * s
                sum_ht += h * t
                sum_ss += s * s
                sum_tt += t * t
        gs, gt = sum_hs / sum_ss, sum_ht / sum_tt  # the samples are symmetric: the fit decouples
        # normal of z = gs s + gt t in world axes: (-(gs f + gt l), 1), normalised
        nx, ny, nz = -(gs * fx + gt * lx), -(gs * fy + gt * ly), 1.0
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        nx, ny, nz = nx / nn, ny / nn, nz / nn
        # in-plane heading and axle (3D) for the footprint test
        ex, ey, ez = fx - (fx * nx + fy * ny) * nx, fy - (fx * nx + fy * ny) * ny, -(fx * nx + fy * ny) * nz
        en = math.sqrt(ex * ex + ey * ey + ez * ez)
        ex, ey, ez = ex / en, ey / en, ez / en
        qx, qy, qz = ny * ez - nz * ey, nz * ex - nx * ez, nx * ey - ny * ex  # n x e: across (left)
        # offset: the highest ground under the tread, less the rim's rise at its distance from the centre
        best = -1e300
        ext_x, ext_y = abs(fx) * r + abs(lx) * hw, abs(fy) * r + abs(ly) * hw  # the tread's box on the grid
        j_lo = max(int(math.ceil((cx - ext_x - p[G_X0]) / cell)), 0)
        j_hi = min(int(math.floor((cx + ext_x - p[G_X0]) / cell)), ncol - 1)
        i_lo = max(int(math.ceil((cy - ext_y - p[G_Y0]) / cell)), 0)
        i_hi = min(int(math.floor((cy + ext_y - p[G_Y0]) / cell)), nrow - 1)
        for i in range(i_lo, i_hi + 1):
            vy = p[G_Y0] + i * cell - cy
            for j in range(j_lo, j_hi + 1):
                vx = p[G_X0] + j * cell - cx
                vz = p[G_BASE] + p[G_SCALE] * hf[adr + i * ncol + j] - cz
                s = vx * ex + vy * ey + vz * ez
                t = vx * qx + vy * qy + vz * qz
                if abs(s) > r or abs(t) >= hw:
                    continue
                o = vx * nx + vy * ny + vz * nz - (r - math.sqrt(r * r - s * s))
                best = max(best, o)
        h_c = _height(hf, adr, nrow, ncol, p, cx, cy) - cz  # the ground under the centre (coarse cells)
        best = max(best, h_c * nz)
        # the plate: the wheel centre projected onto the plane n . (x - c) = best
        m = ints[6 + w]
        mocap_pos[m, 0], mocap_pos[m, 1], mocap_pos[m, 2] = cx + best * nx, cy + best * ny, cz + best * nz
        # rotation taking z to n: about (z x n) by acos(nz)
        half = 0.5 * math.acos(min(max(nz, -1.0), 1.0))
        sx, sy = -ny, nx
        sn = math.sqrt(sx * sx + sy * sy)
        if sn < 1e-12:
            sx, sy, sn = 1.0, 0.0, 1.0
        sh = math.sin(half) / sn
        mocap_quat[m, 0], mocap_quat[m, 1], mocap_quat[m, 2], mocap_quat[m, 3] = math.cos(half), sx * sh, sy * sh, 0.0
