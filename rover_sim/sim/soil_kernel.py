"""Compiled kernel of the default wheel–soil law (:mod:`rover_sim.sim.terramechanics`), run every physics step.

The law is six wheels of scalar arithmetic per 5 ms step. As a plain-float Python loop it cost about 90 us a step,
three quarters of a MuJoCo step of the rover on 4-5 cm cells, so a long drive spent 40 % of its physics time in
it. This module is the same arithmetic, statement for statement, compiled with numba (``nopython``, no fastmath:
IEEE operations in the same order, the same libm calls), so results are bit-identical to the Python loop it
replaced; ``tests/rover_sim/test_soil_kernel.py`` checks the compiled functions against their own Python bodies
(``py_func``) on random inputs and on a drive.

Steps are those of the module docstring of :mod:`rover_sim.sim.terramechanics` (Bekker sinkage, contact patch,
Mohr–Coulomb strength, Janosi–Hanamoto shear state and mobilisation, bristle damping, compaction resistance).
``min``/``max`` are spelled out (:func:`_lo`, :func:`_hi`) with Python's semantics for ties, signed zeros and NaN.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

ROLLING_EPS_M_S = 1e-4  # rim speeds below this count as "not rolling" for the slip ratio
RC_SMOOTHING_M_S = 0.005  # compaction resistance fades in over this hub speed (tanh), no chatter at rest
J_CAP_K = 50.0  # shear displacement is capped at this many K (the law is saturated there)
BRISTLE_DAMPING_RATIO = 0.7  # damping ratio of the shear spring (initial stiffness F_max / 2K) per wheel


@njit(cache=True)
def py_max(a: float, b: float) -> float:
    """Python's ``max(a, b)``: ``a`` unless ``b > a``."""
    return b if b > a else a


@njit(cache=True)
def py_min(a: float, b: float) -> float:
    """Python's ``min(a, b)``: ``a`` unless ``b < a``."""
    return b if b < a else a


@njit(cache=True)
def contact_frame(
    sd: np.ndarray, w: int, nw: int, nx: float, ny: float, nz: float
) -> tuple[float, float, float, float, float, float, float, float]:
    """Wheel ``w``'s contact tangent frame from the sensor block ``sd`` and the unit ground normal ``n``: the
    heading projected on the contact plane (``l``), lateral ``t = n x l``, and the hub velocity along each
    (``v_x``, ``v_y``). Shared by both laws' kernels (this module and ``wr_kernel.py``)."""
    k = 7 * nw + 3 * w  # hub velocity block; headings follow 3 * nw later
    h = k + 3 * nw
    hx, hy, hz = sd[h], sd[h + 1], sd[h + 2]
    hn = hx * nx + hy * ny + hz * nz
    lx, ly, lz = hx - hn * nx, hy - hn * ny, hz - hn * nz
    ln = math.sqrt(lx * lx + ly * ly + lz * lz)
    lx, ly, lz = lx / ln, ly / ln, lz / ln
    tx, ty, tz = ny * lz - nz * ly, nz * lx - nx * lz, nx * ly - ny * lx
    vx_w, vy_w, vz_w = sd[k], sd[k + 1], sd[k + 2]
    return lx, ly, lz, tx, ty, tz, vx_w * lx + vy_w * ly + vz_w * lz, vx_w * tx + vy_w * ty + vz_w * tz


@njit(cache=True)
def shear_decay_gain(rate_per_s: float, dt_s: float) -> tuple[float, float]:
    """Exact one-step integration of ``dj/dt = v_slip - rate * j`` over ``dt_s``: ``j' = j * decay + v_slip *
    gain`` (``gain`` tends to ``dt_s`` as the rate vanishes). Shared by both laws' shear states."""
    if rate_per_s * dt_s > 1e-9:
        decay = math.exp(-rate_per_s * dt_s)
        return decay, (1.0 - decay) / rate_per_s
    return 1.0, dt_s


@njit(cache=True)
def bekker_wheels(
    sd: np.ndarray,
    materials: np.ndarray,
    consts: np.ndarray,
    jx_m: np.ndarray,
    jy_m: np.ndarray,
    patch_m: np.ndarray,
    out: np.ndarray,
    forces: np.ndarray,
    dt_s: float,
    radius_m: float,
    rolling_radius: bool,
    mass_share_kg: float,
) -> None:
    """Tangential wheel–soil forces (world frame) of every wheel into ``forces`` (n, 3).

    ``sd``: the wheel-soil sensor block of ``models/mer/rover.xml`` (per wheel ``[found, Fx, Fy, Fz, px, py, pz]``,
    the wheel's contact force on the ground; then hub velocities, rolling directions, spin rates). ``consts``
    (materials, 9): per-material constants of :class:`~rover_sim.sim.terramechanics.WheelSoilLaw`. The shear state
    ``jx_m``, ``jy_m`` and patch lengths ``patch_m`` are updated in place; ``out`` (6, n) receives W, z, slip,
    f_long, f_lat and contact per wheel.
    """
    r = radius_m
    nw = jx_m.shape[0]
    for w in range(nw):
        c = 7 * w
        # the ground's reaction on the wheel is minus the wheel's force on the ground
        nx, ny, nz = -sd[c + 1], -sd[c + 2], -sd[c + 3]
        W = math.sqrt(nx * nx + ny * ny + nz * nz)
        if W < 1e-6:
            jx_m[w] = 0.0
            jy_m[w] = 0.0
            out[0, w] = 0.0
            out[1, w] = 0.0
            out[3, w] = 0.0
            out[4, w] = 0.0
            out[5, w] = 0.0
            out[2, w] = math.nan
            forces[w, 0] = 0.0
            forces[w, 1] = 0.0
            forces[w, 2] = 0.0
            continue
        nx, ny, nz = nx / W, ny / W, nz / W
        lx, ly, lz, tx, ty, tz, v_x, v_y = contact_frame(sd, w, nw, nx, ny, nz)
        m = materials[w]
        sink_coef, expo, tan_phi, cb, K = consts[m, 0], consts[m, 1], consts[m, 2], consts[m, 3], consts[m, 4]
        ss, tread, n, rc_coef = consts[m, 5], consts[m, 6], consts[m, 7], consts[m, 8]
        # steps 1-3: sinkage (slip-sinkage from the mobilised slip j/L), patch length, shear strength
        i_mob = py_min(py_max(jx_m[w] / patch_m[w], 0.0), 1.0)
        z = (sink_coef * W) ** expo * (1.0 + ss * i_mob)
        v_rim = sd[13 * nw + w] * ((r - py_min(z, 0.5 * r)) if rolling_radius else r)
        L = r * math.acos(py_max(1.0 - z / r, -1.0)) + tread
        patch_m[w] = L
        f_max = cb * L + W * tan_phi
        # step 4: shear displacement, exact integration of dj/dt = v_slip - (V/L) j with V = |r omega|
        decay, gain = shear_decay_gain(abs(v_rim) / L, dt_s)
        jx0, jy0 = jx_m[w], jy_m[w]
        jx = jx0 * decay + (v_rim - v_x) * gain
        jy = jy0 * decay - v_y * gain
        j_cap = J_CAP_K * K
        jx, jy = py_min(py_max(jx, -j_cap), j_cap), py_min(py_max(jy, -j_cap), j_cap)
        jx_m[w], jy_m[w] = jx, jy
        # step 5: Janosi-Hanamoto mobilisation averaged over the patch, along the shear displacement
        j = math.sqrt(jx * jx + jy * jy)
        if j > 1e-12:
            x = j / K
            mob = 1.0 - (1.0 - math.exp(-x)) / x if x > 1e-6 else 0.5 * x
            s = f_max * mob / j
            f_long, f_lat = s * jx, s * jy
        else:
            f_long = f_lat = 0.0
        # bristle damping (LuGre sigma_1), critically damped for a sixth of the rover's mass
        sigma1 = BRISTLE_DAMPING_RATIO * 2.0 * math.sqrt(f_max / (2.0 * K) * mass_share_kg)
        f_long += sigma1 * (jx - jx0) / dt_s
        f_lat += sigma1 * (jy - jy0) / dt_s
        f_t = math.sqrt(f_long * f_long + f_lat * f_lat)
        if f_t > f_max:  # the soil cannot carry more than its shear strength
            f_long, f_lat = f_long * f_max / f_t, f_lat * f_max / f_t
        # step 6: compaction resistance, bounded
        r_c = py_min(rc_coef * z ** (n + 1.0), 0.5 * W)
        f_long -= r_c * math.tanh(v_x / RC_SMOOTHING_M_S)
        forces[w, 0] = f_long * lx + f_lat * tx
        forces[w, 1] = f_long * ly + f_lat * ty
        forces[w, 2] = f_long * lz + f_lat * tz
        out[0, w], out[1, w], out[3, w], out[4, w], out[5, w] = W, z, f_long, f_lat, 1.0
        out[2, w] = (v_rim - v_x) / v_rim if abs(v_rim) > ROLLING_EPS_M_S else math.nan


@njit(cache=True)
def materials_under(
    sd: np.ndarray,
    heights_m: np.ndarray,
    material_grid: np.ndarray,
    grid: np.ndarray,
    rock_margin_m: float,
    rock_material: int,
    out: np.ndarray,
) -> None:
    """Material index under each wheel's contact point into ``out``; a contact more than ``rock_margin_m`` above
    the heightfield is on a rock. ``grid`` = (origin_x, origin_y, half_x, half_y, 1 / cell) of the heightfield."""
    ox, oy, half_x, half_y, inv_cell = grid[0], grid[1], grid[2], grid[3], grid[4]
    nrow, ncol = heights_m.shape
    for w in range(out.shape[0]):
        c = 7 * w
        x, y, z = sd[c + 4], sd[c + 5], sd[c + 6]
        j = int(py_min(py_max(int((x - ox + half_x) * inv_cell + 0.5), 0), ncol - 1))
        i = int(py_min(py_max(int((y - oy + half_y) * inv_cell + 0.5), 0), nrow - 1))
        out[w] = rock_material if z > heights_m[i, j] + rock_margin_m else material_grid[i, j]


@njit(cache=True)
def apply_wheel_wrenches(sd: np.ndarray, forces: np.ndarray, body_ids: np.ndarray, xipos: np.ndarray,
                         xfrc_applied: np.ndarray) -> None:  # fmt: skip
    """Each wheel's force applied at its contact point, as the world wrench about its body's centre of mass
    (``MjData.xipos``), written into the wheel bodies' rows of ``MjData.xfrc_applied`` (force, torque)."""
    for w in range(forces.shape[0]):
        c, b = 7 * w, body_ids[w]
        fx, fy, fz = forces[w, 0], forces[w, 1], forces[w, 2]
        rx, ry, rz = sd[c + 4] - xipos[b, 0], sd[c + 5] - xipos[b, 1], sd[c + 6] - xipos[b, 2]
        xfrc_applied[b, 0], xfrc_applied[b, 1], xfrc_applied[b, 2] = fx, fy, fz
        xfrc_applied[b, 3] = ry * fz - rz * fy
        xfrc_applied[b, 4] = rz * fx - rx * fz
        xfrc_applied[b, 5] = rx * fy - ry * fx
