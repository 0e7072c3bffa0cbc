"""Compiled kernels of the Wong–Reece law and the deformable terrain, run every physics step.

The law (:mod:`rover_sim.sim.terramechanics_wr`), the table look-up (:mod:`rover_sim.sim.soil_tables`), the wheel
wrenches and the rut writes (:mod:`rover_sim.sim.deform`) are six wheels of scalar arithmetic per 5 ms step. As a
plain-float Python loop they cost about 130 us a step, more than the MuJoCo step itself on 0.04 m cells. This
module is the same arithmetic, statement for statement, compiled with numba (``nopython``, no fastmath: IEEE
operations in the same order, the same libm calls), so results are bit-identical to the Python loops it replaced;
``tests/rover_sim/test_wr_kernel.py`` checks each compiled function against its own Python body (``py_func``).

Two spellings keep Python's semantics where numba's differ: ``min``/``max`` (:func:`_lo`, :func:`_hi`: ties,
signed zeros, NaN) and ``math.hypot``, which CPython computes correctly rounded (its ``vector_norm``), where the
libm ``hypot`` numba calls differs in the last bit for about one input in 200 (:func:`py_hypot`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from rover_sim.sim.soil_kernel import contact_frame, py_max, py_min, shear_decay_gain
from rover_sim.sim.soil_tables import N_LOAD, N_SLIP

BOW_M = 0.002  # advance over which the front-loaded (resisting) stress distribution forms
VEL_FILTER_S = 0.1  # window of the net motion that renews the soil under the patch
ROLLING_EPS_M_S = 1e-4  # rim speeds below this count as "not rolling" for the reported slip ratio
BRISTLE_DAMPING_RATIO = 0.7  # damping ratio of the shear spring (initial stiffness F_max / 2 K_0) per wheel

UPDATE_M = 0.02  # contact travel between rut writes (half a 4 cm cell)
BERM_CELLS = 2
BERM_SPREAD = 5.0  # a berm is at least this many rut depths wide

# rows of the law's per-wheel output block (WheelSoilLaw.out_state)
OUT_LOAD, OUT_SINKAGE, OUT_SLIP, OUT_LONG, OUT_LAT, OUT_CONTACT, OUT_TORQUE = range(7)
# columns of the per-material constants (WheelSoilLaw.consts): C_K the longitudinal curve's short scale, C_K0 its
# initial one (soil_tables.SoilParams.initial_shear_modulus_m, for the shear spring's damping), C_KY the lateral K_y
C_INV_DU, C_TAN_PHI, C_COHESION, C_K, C_KY, C_N0, C_N1, C_K0 = range(8)
# entries of the deformable terrain's float parameters (DeformableTerrain)
P_CELL, P_X0, P_Y0, P_BASE, P_SCALE, P_ALPHA, P_WIDTH, P_WALL_TAN = range(8)
_SPLIT = 134217729.0  # 2^27 + 1: Veltkamp's splitter for a double


@njit(cache=True)
def _two_product(a: float, b: float) -> tuple[float, float]:
    """``a * b`` and its exact rounding error (Dekker 1971, Veltkamp split), as CPython's ``dl_mul``."""
    p = a * b
    t = _SPLIT * a
    a_hi = t - (t - a)
    a_lo = a - a_hi
    t = _SPLIT * b
    b_hi = t - (t - b)
    b_lo = b - b_hi
    return p, ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo


@njit(cache=True)
def py_hypot(x: float, y: float) -> float:
    """CPython 3.11's ``math.hypot(x, y)`` (``Modules/mathmodule.c``, ``vector_norm``): correctly rounded."""
    ax, ay = abs(x), abs(y)
    found_nan = math.isnan(ax) or math.isnan(ay)
    m = 0.0
    if ax > m:
        m = ax
    if ay > m:
        m = ay
    if math.isinf(m):
        return m
    if found_nan:
        return math.nan
    if m == 0.0:
        return m
    _, max_e = math.frexp(m)
    if max_e < -1023:  # ldexp(1.0, -max_e) would overflow: divide by the largest instead
        csum, frac = 1.0, 0.0
        for v in (ax, ay):
            x = v / m
            x = x * x
            old = csum
            csum += x
            frac += (old - csum) + x
        return m * math.sqrt(csum - 1.0 + frac)
    scale = math.ldexp(1.0, -max_e)
    csum, frac1, frac2 = 1.0, 0.0, 0.0
    for v in (ax, ay):
        p_hi, p_lo = _two_product(v * scale, v * scale)
        s = csum + p_hi  # lossless addition (csum >= p_hi)
        frac2 += p_hi - (s - csum)
        csum = s
        frac1 += p_lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    p_hi, p_lo = _two_product(-h, h)
    s = csum + p_hi
    frac2 += p_hi - (s - csum)
    csum = s
    frac1 += p_lo
    h += (csum - 1.0 + (frac1 + frac2)) / (2.0 * h)  # differential correction
    return h / scale


@njit(cache=True)
def table_lookup(rows: np.ndarray, inv_du: float, load_n: float, slip: float) -> tuple[float, ...]:
    """Bilinear read of one material's table ``rows`` (``soil_tables.build_table``, as an (N_SLIP * N_LOAD, 7)
    array) at (load, slip): (sinkage m, H/W, R/W, T/(W r), contact length m, area m^2, Fb/W)."""
    u = math.sqrt(py_max(load_n, 0.0)) * inv_du
    iu = min(int(u), N_LOAD - 2)
    fu = py_min(u - iu, 1.0)
    v = (py_min(py_max(slip, -1.0), 1.0) + 1.0) * 0.5 * (N_SLIP - 1)
    iv = min(int(v), N_SLIP - 2)
    fv = v - iv
    k = iv * N_LOAD + iu
    a, b, c, d = rows[k], rows[k + 1], rows[k + N_LOAD], rows[k + N_LOAD + 1]
    w00, w01, w10, w11 = (1 - fv) * (1 - fu), (1 - fv) * fu, fv * (1 - fu), fv * fu
    return (
        w00 * a[0] + w01 * b[0] + w10 * c[0] + w11 * d[0],
        w00 * a[1] + w01 * b[1] + w10 * c[1] + w11 * d[1],
        w00 * a[2] + w01 * b[2] + w10 * c[2] + w11 * d[2],
        w00 * a[3] + w01 * b[3] + w10 * c[3] + w11 * d[3],
        w00 * a[4] + w01 * b[4] + w10 * c[4] + w11 * d[4],
        w00 * a[5] + w01 * b[5] + w10 * c[5] + w11 * d[5],
        w00 * a[6] + w01 * b[6] + w10 * c[6] + w11 * d[6],
    )


@njit(cache=True)
def _lift_off(sd: np.ndarray, w: int, nw: int, vf: np.ndarray, jx_m: np.ndarray, jy_m: np.ndarray,
              patch_m: np.ndarray, dt_s: float, alpha: float, radius_m: float) -> None:  # fmt: skip
    """Shear states of wheel ``w`` while it is out of contact: renewed by its advance, no source."""
    k = 7 * nw + 3 * w
    h = k + 3 * nw
    vx_w, vy_w = sd[k], sd[k + 1]
    hx, hy = sd[h], sd[h + 1]
    hn = py_hypot(hx, hy)
    if hn == 0.0:  # Python's `hypot(...) or 1.0`
        hn = 1.0
    v_x = (vx_w * hx + vy_w * hy) / hn
    v_y = (-vx_w * hy + vy_w * hx) / hn
    vf[w, 0] += alpha * (sd[13 * nw + w] * radius_m - vf[w, 0])
    vf[w, 1] += alpha * (v_x - vf[w, 1])
    vf[w, 2] += alpha * (v_y - vf[w, 2])
    decay = math.exp(-py_max(py_max(abs(vf[w, 0]), abs(vf[w, 1])), abs(vf[w, 2])) / patch_m[w] * dt_s)
    jx_m[w] *= decay
    jy_m[w] *= decay


@njit(cache=True)
def wr_wheels(
    sd: np.ndarray,
    materials: np.ndarray,
    tables: np.ndarray,
    consts: np.ndarray,
    state: np.ndarray,
    vf: np.ndarray,
    out: np.ndarray,
    axles: np.ndarray,
    forces: np.ndarray,
    dt_s: float,
    radius_m: float,
    mass_share_kg: float,
) -> None:
    """The Wong–Reece law for every wheel (steps 1-5 of :mod:`rover_sim.sim.terramechanics_wr`): the force on the
    wheel (world frame, at the contact point) and the soil torque about its axle into ``forces`` (n, 4).

    ``sd``: the wheel-soil sensor block of ``models/mer/rover.xml``. ``tables`` (materials, N_SLIP * N_LOAD, 7),
    ``consts`` (materials, 7: ``C_*`` columns). ``state`` (5, n): rows jx, jy, bow, patch length, presink (the
    rut depth ahead, set by the deformable terrain), updated in place; ``vf`` (n, 3) the low-passed rim,
    longitudinal and lateral speeds; ``out`` (7, n) the ``OUT_*`` rows; ``axles`` (n, 3) each wheel's lateral
    unit vector of its last contact.
    """
    r = radius_m
    nw = forces.shape[0]
    jx_m, jy_m, bow_m, patch_m, presink_m = state[0], state[1], state[2], state[3], state[4]
    alpha = dt_s / (VEL_FILTER_S + dt_s)
    for w in range(nw):
        c = 7 * w
        nx, ny, nz = -sd[c + 1], -sd[c + 2], -sd[c + 3]
        W = math.sqrt(nx * nx + ny * ny + nz * nz)
        forces[w, 0] = forces[w, 1] = forces[w, 2] = forces[w, 3] = 0.0
        if W < 1e-6:
            # lifted off (a bounce): the sheared soil stays and is only renewed by the advance
            _lift_off(sd, w, nw, vf, jx_m, jy_m, patch_m, dt_s, alpha, r)
            out[0, w] = out[1, w] = out[3, w] = out[4, w] = out[5, w] = out[6, w] = 0.0
            out[2, w] = math.nan
            continue
        nx, ny, nz = nx / W, ny / W, nz / W
        lx, ly, lz, tx, ty, tz, v_x, v_y = contact_frame(sd, w, nw, nx, ny, nz)
        v_rim = sd[13 * nw + w] * r
        mat = materials[w]
        rows = tables[mat]
        inv_du, tan_phi, coh = consts[mat, C_INV_DU], consts[mat, C_TAN_PHI], consts[mat, C_COHESION]
        k0, Ky, n0, n1 = consts[mat, C_K0], consts[mat, C_KY], consts[mat, C_N0], consts[mat, C_N1]
        # step 1: shear states, renewed by the net advance over the soil
        vf[w, 0] += alpha * (v_rim - vf[w, 0])
        vf[w, 1] += alpha * (v_x - vf[w, 1])
        vf[w, 2] += alpha * (v_y - vf[w, 2])
        V = py_max(py_max(abs(vf[w, 0]), abs(vf[w, 1])), abs(vf[w, 2]))
        L = patch_m[w]
        decay, gain = shear_decay_gain(V / L, dt_s)
        jx0, jy0 = jx_m[w], jy_m[w]
        jx = py_min(py_max(jx0 * decay + (v_rim - v_x) * gain, -L), L)
        jy = py_min(py_max(jy0 * decay - v_y * gain, -L), L)
        jx_m[w], jy_m[w] = jx, jy
        i_m = jx / L
        # step 2: the steady-state stresses at the mobilised slip
        z, hn_, rn, tn, Lp, A, fbn = table_lookup(rows, inv_du, W, i_m)
        patch_m[w] = Lp
        lat = abs(jy) / Lp
        if lat > abs(i_m):  # lateral sinkage
            z = table_lookup(rows, inv_du, W, lat)[0]
        # step 3: compaction resistance as a reaction, reduced in an earlier rut (Bekker's compaction work)
        bow = py_min(py_max(bow_m[w] + v_x * dt_s, -BOW_M), BOW_M)
        bow_m[w] = bow
        zp = presink_m[w]
        fresh = 1.0 - (zp / z) ** (1.0 + n0 + n1 * abs(i_m)) if z > zp else 0.0
        f_long = W * (hn_ - rn * fresh * bow / BOW_M)
        # step 4: lateral shear with its own modulus, mean mobilisation over the patch, plus side-wall bulldozing
        f_max = coh * A + W * tan_phi
        q = abs(jy) / Ky
        mob = 1.0 - (1.0 - math.exp(-q)) / q if q > 1e-6 else 0.5 * q
        f_lat = mob * f_max * (1.0 if jy >= 0 else -1.0)
        f_t = math.sqrt(W * W * hn_ * hn_ + f_lat * f_lat)
        if f_t > f_max:  # longitudinal and lateral shear share the strength
            f_lat *= f_max / f_t
        f_lat += mob * W * fbn * (1.0 if jy >= 0 else -1.0)
        # step 5: damping of the shear springs (LuGre sigma_1), zero at steady state
        sigma1 = BRISTLE_DAMPING_RATIO * 2.0 * math.sqrt(f_max / (2.0 * k0) * mass_share_kg)
        f_long += sigma1 * (jx - jx0) / dt_s
        f_lat += sigma1 * (k0 / Ky) * (jy - jy0) / dt_s
        f_cap = f_max + W * fbn + W * rn
        f_t = math.sqrt(f_long * f_long + f_lat * f_lat)
        if f_t > f_cap:
            f_long, f_lat = f_long * f_cap / f_t, f_lat * f_cap / f_t
        torque = W * r * tn
        forces[w, 0] = f_long * lx + f_lat * tx
        forces[w, 1] = f_long * ly + f_lat * ty
        forces[w, 2] = f_long * lz + f_lat * tz
        forces[w, 3] = torque
        axles[w, 0], axles[w, 1], axles[w, 2] = tx, ty, tz
        out[0, w], out[1, w], out[3, w], out[4, w], out[5, w], out[6, w] = W, z, f_long, f_lat, 1.0, torque
        out[2, w] = (v_rim - v_x) / v_rim if abs(v_rim) > ROLLING_EPS_M_S else math.nan


@njit(cache=True)
def wr_wrenches(sd: np.ndarray, forces: np.ndarray, axles: np.ndarray, body_ids: np.ndarray, xipos: np.ndarray,
                xfrc_applied: np.ndarray) -> None:  # fmt: skip
    """Each wheel's soil force (``forces[:, :3]``, at its contact point) as the world wrench about its body's
    centre of mass, with the torque about the axle replaced by the law's soil torque ``-forces[:, 3]`` (resisting
    the spin; not the lever of the net force), into the wheel bodies' rows of ``MjData.xfrc_applied``."""
    for w in range(forces.shape[0]):
        c, b = 7 * w, body_ids[w]
        fx, fy, fz, T = forces[w, 0], forces[w, 1], forces[w, 2], forces[w, 3]
        rx, ry, rz = sd[c + 4] - xipos[b, 0], sd[c + 5] - xipos[b, 1], sd[c + 6] - xipos[b, 2]
        mx, my, mz = ry * fz - rz * fy, rz * fx - rx * fz, rx * fy - ry * fx
        ax, ay, az = axles[w, 0], axles[w, 1], axles[w, 2]
        corr = -T - (mx * ax + my * ay + mz * az)
        xfrc_applied[b, 0], xfrc_applied[b, 1], xfrc_applied[b, 2] = fx, fy, fz
        xfrc_applied[b, 3] = mx + corr * ax
        xfrc_applied[b, 4] = my + corr * ay
        xfrc_applied[b, 5] = mz + corr * az


@njit(cache=True)
def _cell_of(x: float, y: float, p: np.ndarray, nrow: int, ncol: int) -> tuple[int, int]:
    """Nearest cell (row, column) of (x, y), clamped to the grid."""
    j = min(max(int((x - p[P_X0]) / p[P_CELL] + 0.5), 0), ncol - 1)
    i = min(max(int((y - p[P_Y0]) / p[P_CELL] + 0.5), 0), nrow - 1)
    return i, j


@njit(cache=True)
def _grow_box(dirty: np.ndarray, k: int, ci: int, cj: int, span: int, nrow: int, ncol: int) -> None:
    """Grow the inclusive cell box ``dirty[k] = (valid, i0, i1, j0, j1)`` by the square of ``span`` about (ci, cj)."""
    if dirty[k, 0] == 0:
        dirty[k, 0], dirty[k, 1], dirty[k, 2], dirty[k, 3], dirty[k, 4] = 1, ci, ci, cj, cj
    dirty[k, 1] = max(min(dirty[k, 1], ci - span), 0)
    dirty[k, 2] = min(max(dirty[k, 2], ci + span), nrow - 1)
    dirty[k, 3] = max(min(dirty[k, 3], cj - span), 0)
    dirty[k, 4] = min(max(dirty[k, 4], cj + span), ncol - 1)


@njit(cache=True)
def write_rut(h: np.ndarray, h0: np.ndarray, soft: np.ndarray, hfield: np.ndarray, adr: int, p: np.ndarray,
              dirty: np.ndarray, px: float, py: float, hx: float, hy: float, z: float, lp: float) -> None:  # fmt: skip
    """One wheel's rut (sinkage ``z``, contact length ``lp``, heading (hx, hy)) at (px, py) into the heights ``h``
    and ``hfield`` (MuJoCo's ``hfield_data`` from ``adr``), its displaced soil into the berms beside it; grows the
    ``dirty`` boxes over the changed cells. See :mod:`rover_sim.sim.deform` for the shape."""
    nrow, ncol = h.shape
    cell, base, scale, width, wall_tan = p[P_CELL], p[P_BASE], p[P_SCALE], p[P_WIDTH], p[P_WALL_TAN]
    # ahead: the patch plus the travel until the next write and a cell; behind the same, so a wheel that digs in
    # without advancing has a pit its rim does not touch at the back either (the ground plate sees the floor)
    front, half_w = 0.5 * lp + UPDATE_M + 1.5 * cell, 0.5 * width
    back = front
    shoulder = half_w + z / wall_tan  # the rut's walls stand at the soil's angle of repose
    reach = shoulder + py_max(BERM_CELLS * cell, BERM_SPREAD * z)
    span = int(math.ceil(py_max(front, reach) / cell)) + 1
    ci, cj = _cell_of(px, py, p, nrow, ncol)
    displaced = 0.0
    berm = np.empty((2 * span + 1) * (2 * span + 1), dtype=np.int64)
    n_berm = 0
    for i in range(max(ci - span, 0), min(ci + span + 1, nrow)):
        dy = p[P_Y0] + i * cell - py
        for j in range(max(cj - span, 0), min(cj + span + 1, ncol)):
            if not soft[i, j]:
                continue
            dx = p[P_X0] + j * cell - px
            along, across = dx * hx + dy * hy, abs(-dx * hy + dy * hx)
            if along > front or along < -back:
                continue
            if across < shoulder:
                target = h0[i, j] - z  # the tread; beside it, the wall
                if across > half_w:
                    target += (across - half_w) * wall_tan
                if target < h[i, j]:
                    displaced += h[i, j] - target
                    h[i, j] = target
                    hfield[adr + i * ncol + j] = (h[i, j] - base) / scale
            elif across <= reach:
                berm[n_berm] = i * ncol + j
                n_berm += 1
    if displaced > 0.0 and n_berm > 0:
        dh = displaced / n_berm
        for k in range(n_berm):
            i, j = berm[k] // ncol, berm[k] % ncol
            h[i, j] += dh
            hfield[adr + i * ncol + j] = (h[i, j] - base) / scale
    if displaced > 0.0:
        for k in range(dirty.shape[0]):
            _grow_box(dirty, k, ci, cj, span, nrow, ncol)


@njit(cache=True)
def deform_after_law(
    sd: np.ndarray,
    materials: np.ndarray,
    soft_material: np.ndarray,
    law_out: np.ndarray,
    law_state: np.ndarray,
    axles: np.ndarray,
    xpos: np.ndarray,
    wheel_ids: np.ndarray,
    h: np.ndarray,
    h0: np.ndarray,
    soft: np.ndarray,
    hfield: np.ndarray,
    adr: int,
    p: np.ndarray,
    zf: np.ndarray,
    last: np.ndarray,
    dirty: np.ndarray,
) -> None:
    """Per physics step, after the law: each loaded wheel on deformable soil reads the rut depth ahead of it into
    the law's presink (``law_state[4]``) and, once its contact has moved ``UPDATE_M`` or its low-passed sinkage
    ``zf`` grew 1 mm since its last write (``last`` (n, 3): x, y, sinkage), writes its rut (:func:`write_rut`)."""
    nrow, ncol = h.shape
    presink_m, patch_m = law_state[4], law_state[3]
    cell, alpha = p[P_CELL], p[P_ALPHA]
    for w in range(wheel_ids.shape[0]):
        if law_out[0, w] <= 0.0 or not soft_material[materials[w]]:
            presink_m[w] = zf[w] = 0.0
            continue
        hx, hy = axles[w, 1], -axles[w, 0]  # heading = axle x up, projected
        hn = py_hypot(hx, hy)
        if hn == 0.0:  # Python's `hypot(...) or 1.0`
            hn = 1.0
        hx, hy = hx / hn, hy / hn
        # the rut lies in the wheel's mid-plane: the contact point's offset from the wheel centre along the
        # heading is kept, the sideways one dropped
        b = wheel_ids[w]
        cx, cy = xpos[b, 0], xpos[b, 1]
        along = (sd[7 * w + 4] - cx) * hx + (sd[7 * w + 5] - cy) * hy
        px, py = cx + along * hx, cy + along * hy
        lp = patch_m[w]
        lead = 0.5 * lp + UPDATE_M + 2.5 * cell  # beyond this wheel's own footprint
        i, j = _cell_of(px + lead * hx, py + lead * hy, p, nrow, ncol)
        presink_m[w] = py_max(h0[i, j] - h[i, j], 0.0)
        lx, ly, lz = last[w, 0], last[w, 1], last[w, 2]
        z = zf[w] = zf[w] + alpha * (law_out[1, w] - zf[w])
        if (px - lx) ** 2 + (py - ly) ** 2 < UPDATE_M * UPDATE_M and z < lz + 0.001:
            continue
        last[w, 0], last[w, 1], last[w, 2] = px, py, z
        write_rut(h, h0, soft, hfield, adr, p, dirty, px, py, hx, hy, z, lp)
