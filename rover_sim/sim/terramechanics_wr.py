"""Wheel–soil law: Wong–Reece stress distribution under the MER wheel, driven by a shear-displacement state.

EXPERIMENTAL and opt-in (``[physics] soil_model = "wong_reece"``); the default law is
:mod:`rover_sim.sim.terramechanics` (Bekker). See the README section on the experimental soil for what it misses.

MuJoCo supplies only the *normal* wheel load (wheel contacts are frictionless, ``condim=1``); every tangential
force and the soil's torque on each wheel come from this module, for all six wheels each physics step. Slip is an
outcome of the soil law, the load on each wheel and the slope — nothing is scripted.

The steady-state physics is the Wong–Reece integration of :mod:`rover_sim.sim.soil_tables` (Bekker normal stress
with Ding et al.'s slip-dependent sinkage exponent, Mohr–Coulomb / Janosi–Hanamoto shear, the MER wheel's grousers
and compliant rim, Hegedus bulldozing), tabulated once per material over (load, slip). Per wheel and step:

1. **Longitudinal shear state** ``j_x``: the shear displacement the soil has accumulated at the rear of the patch.
   Under a wheel rolling at steady slip ``i`` it is ``i L`` (``L`` the contact length; Wong–Reece's ``j(theta2)``).
   It obeys ``dj/dt = (v_rim - v_x) - (V / L) j`` with ``V = max(|v_rim|, |v_x|, |v_y|)``: slip displaces the soil,
   fresh soil enters the patch as the wheel advances over it. ``V`` is taken from the *net* motion (the velocities
   low-passed over 0.1 s), so vibration of a parked wheel does not renew the soil and rectify into creep; steady
   motion is unaffected. The slip the soil has mobilised is ``i_m = j_x / L`` (in ``[-1, 1]``; ``-1`` a dragged,
   locked wheel); at rest ``j`` is held, so a held wheel is held by the soil acting as a spring.
2. **Stresses**: sinkage ``z``, thrust ``H``, compaction resistance ``R`` and torque ``T`` at (load, ``i_m``) from
   the table (bilinear). Nothing depends on speed: quasi-static slip is the same at 1 and 5 cm/s.
3. **Compaction resistance as a reaction**: the front-loaded stress distribution that resists motion exists only
   once the wheel pushes into the soil ahead. A bow state ``e`` (clamped to ``+-BOW_M``, the displacement over which
   it forms) makes the resistance ``R e / BOW_M``: full while advancing, relaxed after the wheel stops or reverses
   (so a parked wheel is not pushed back). In a rut of an earlier pass (depth ``z_p``, from the deformable
   terrain) only the new compaction resists: ``R (1 - (z_p / z)^(n+1))`` (Bekker's compaction work from
   ``z_p`` to ``z``; multipass).
4. **Lateral**: its own shear state ``j_y`` (steady ``-v_y L / V``, Ishigami et al. 2007) with its own modulus
   ``K_y``, the mean Janosi–Hanamoto mobilisation over the patch, plus the side-wall bulldozing of the sunk wheel
   face (Hegedus); lateral slip also deepens the sinkage (the table's sinkage at the lateral slip ``|j_y| / L``
   when larger than ``|i_m|``: lateral sinkage).
5. **Strength**: the tangential shear is bounded by ``c A + W tan(phi)`` (bulldozing on top); a damping term on the
   shear states (LuGre ``sigma_1``) keeps the stiff rock springs stable at a 5 ms step; it vanishes at steady state.

Output per wheel: the force on the wheel (world frame, at the contact point) and the soil's resisting torque about
the axle ``T`` (the drive motor supplies it).

Implementation note: numpy's per-call overhead on 6-element arrays would cost 5-10x the MuJoCo step, so
:meth:`WheelSoilLaw.evaluate` is a plain-float loop; state and outputs are exposed as numpy arrays for logging.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from rover_sim.sim.soil_tables import N_LOAD, N_SLIP, SoilParams, WheelParams, build_table
from rover_sim.sim.terramechanics import pack_inputs  # noqa: F401 - the same input layout as the default law

__all__ = [
    "BEDROCK", "DRIFT", "MATERIALS", "MIXED", "SAND", "SoilParams", "WheelParams", "WheelSoilLaw", "WheelSoilState",
]

# Loose Martian sand. Every value inside the published ranges (REFERENCE.md section 2: c 0.2-1 kPa, phi 28-37 deg,
# K 1-2.5 cm, k_c 1e3-1.4e4, k_phi 8e5-2.3e6, n about 1; Ding et al. 2011 for n1; Wong-Reece a0 0.4, a1 0.15 and
# the density of Toyoura sand from Ishigami et al. 2007). The combination is a CALIBRATION to the MER uphill slip
# record (about 50 % at 17-20 deg, about 100 % beyond 25 deg): see `rover-sim bench slip`, which reports the
# held-out checks beside it. Recalibrated after the bounce fix (the shear state no longer resets on lift-off, which
# had made the rover slip more): phi 34 -> 29 deg and c 0.2 -> 1 kPa (both inside the ranges above), chosen with the
# single-wheel DP/W curve against the 17-20 deg anchor and the 100 % point, then checked on the rover at 20 deg.
SAND = SoilParams(
    name="sand",
    cohesion_pa=1000.0,
    friction_angle_deg=29.0,
    shear_modulus_m=0.025,
    lateral_shear_modulus_m=0.010,
    k_c=1.4e4,
    k_phi=2.3e6,
    n0=1.0,
    n1=0.5,
    a0=0.40,
    a1=0.15,
    density_kg_m3=1600.0,
)

# Bedrock outcrop: rigid (no sinkage, never deformed), aluminium grousers on rock (phi 42 deg), shear mobilised over
# the rim's elastic deflection (about 1.5 mm).
BEDROCK = SoilParams(
    name="bedrock",
    cohesion_pa=0.0,
    friction_angle_deg=42.0,
    shear_modulus_m=0.0015,
    lateral_shear_modulus_m=0.0015,
    k_c=0.0,
    k_phi=1.0e9,
    n0=1.0,
    n1=0.0,
    a0=0.40,
    a1=0.0,
    density_kg_m3=2200.0,
    deformable=False,
)

# Thin sand over rock / gravel (Spirit's Columbia Hills soils): between the two.
MIXED = SoilParams(
    name="mixed",
    cohesion_pa=500.0,
    friction_angle_deg=36.0,
    shear_modulus_m=0.008,
    lateral_shear_modulus_m=0.008,
    k_c=5.0e3,
    k_phi=2.3e6,
    n0=1.0,
    n1=0.2,
    a0=0.40,
    a1=0.10,
    density_kg_m3=1800.0,
)

# Loose, fine-grained, porous drift: the soil of Opportunity's Purgatory ripple (Sol 446), where the wheels dug in to
# their hubs. Published for Martian drift: friction angle 26-28 deg (Pathfinder drifts, Moore et al. 1999, JGR 104
# E4) and about 18 deg (Viking Lander 1 drift, Moore et al. 1987); cohesion small, about 0.01-0.1 kPa (Viking 1
# drift trench walls, Shorthill/Moore et al. 1977) and bulk density about 1150 kg/m^3 (Viking drift, Moore et al.
# 1987). Chosen inside those: phi 25 deg, c 0.1 kPa, 1200 kg/m^3. No Bekker moduli are published for Martian drift
# ("porous, compressible", Moore 1999): k_c 0 and k_phi 1e5 (about an eighth of the sand range's low end in
# REFERENCE.md section 2, as for very loose, fine soils) are a CALIBRATION CHOICE: the static sinkage of a MER wheel
# under a sixth of the rover's weight is then about 7 cm, near its hub (12.5 cm) at high slip, as at Purgatory.
# Shear modulus K at the loose end of the sand range (2.5 cm); slip-sinkage n1, a0, a1 as for SAND. Not tuned on
# the purgatory_ripple scenarios' outcomes (they judge it).
DRIFT = SoilParams(
    name="drift",
    cohesion_pa=100.0,
    friction_angle_deg=25.0,
    shear_modulus_m=0.025,
    lateral_shear_modulus_m=0.010,
    k_c=0.0,
    k_phi=1.0e5,
    n0=1.0,
    n1=0.5,
    a0=0.40,
    a1=0.15,
    density_kg_m3=1200.0,
)

# Index order matches terrains.Material (SAND=0, BEDROCK=1, MIXED=2, DRIFT=3); rocks are treated as BEDROCK.
MATERIALS: tuple[SoilParams, ...] = (SAND, BEDROCK, MIXED, DRIFT)

BOW_M = 0.002  # advance over which the front-loaded (resisting) stress distribution forms
_VEL_FILTER_S = 0.1  # window of the net motion that renews the soil under the patch
_ROLLING_EPS_M_S = 1e-4  # rim speeds below this count as "not rolling" for the reported slip ratio
_BRISTLE_DAMPING_RATIO = 0.7  # damping ratio of the shear spring (initial stiffness F_max / 2K) per wheel


@dataclass
class WheelSoilState:
    """Per-wheel outputs of the last evaluation (ground truth for logging/evaluation)."""

    normal_force_n: np.ndarray  # (n,)
    sinkage_m: np.ndarray  # (n,) below the undisturbed surface
    slip: np.ndarray  # (n,) longitudinal slip ratio, NaN where not rolling or not in contact
    traction_n: np.ndarray  # (n,) longitudinal force (wheel frame), net of compaction resistance
    lateral_n: np.ndarray  # (n,) lateral force
    torque_nm: np.ndarray  # (n,) soil torque resisting the wheel's rotation
    in_contact: np.ndarray  # (n,) bool


@lru_cache(maxsize=16)
def _table(soil: SoilParams, wheel: WheelParams) -> tuple[list[tuple[float, ...]], float]:
    return build_table(soil, wheel)


class WheelSoilLaw:
    """Wheel–soil force law for ``n_wheels`` MER wheels. ``materials[k]`` is the soil of material index ``k``."""

    def __init__(
        self,
        radius_m: float = 0.125,
        width_m: float = 0.16,
        n_wheels: int = 6,
        materials: tuple[SoilParams, ...] = MATERIALS,
        mass_share_kg: float = 29.0,
        wheel: WheelParams | None = None,
    ) -> None:
        self.wheel = wheel or WheelParams(radius_m=radius_m, width_m=width_m)
        self.radius_m = self.wheel.radius_m
        self.width_m = self.wheel.width_m
        self.mass_share_kg = mass_share_kg  # vehicle mass per wheel, for the shear-state damping
        self.n_wheels = n_wheels
        self.materials = materials
        self._consts = []
        for m in materials:
            rows, max_load = _table(m, self.wheel)
            self._consts.append(
                (
                    rows,
                    (N_LOAD - 1) / math.sqrt(max_load),
                    math.tan(math.radians(m.friction_angle_deg)),
                    m.cohesion_pa,
                    m.shear_modulus_m,
                    m.lateral_shear_modulus_m,
                    m.n0,
                    m.n1,
                )
            )
        self.reset()

    def reset(self) -> None:
        n = self.n_wheels
        self._jx = [0.0] * n  # shear displacement states (m)
        self._jy = [0.0] * n
        self._bow = [0.0] * n  # bow state of the compaction resistance (m)
        self._vf = [[0.0, 0.0, 0.0] for _ in range(n)]  # low-passed rim, longitudinal and lateral speeds
        self._patch = [0.1] * n
        self.presink_m = [0.0] * n  # rut depth of earlier passes at each wheel (set by the deformable terrain)
        self._out = [[0.0] * n for _ in range(7)]  # W, z, slip, f_long, f_lat, contact, torque
        self.axles = [(0.0, 1.0, 0.0)] * n  # wheel axle (lateral) unit vectors of the last evaluation, world

    @property
    def j_m(self) -> np.ndarray:
        """(n, 2) shear displacement state (longitudinal, lateral), metres."""
        return np.array([self._jx, self._jy]).T

    @property
    def patch_m(self) -> np.ndarray:
        """(n,) contact length of the last evaluation, metres."""
        return np.array(self._patch)

    def out_state(self) -> list[list[float]]:
        """The last evaluation's raw per-wheel lists (load, sinkage, slip, f_long, f_lat, contact, torque)."""
        return self._out

    def patch_length(self, wheel: int) -> float:
        return self._patch[wheel]

    @property
    def state(self) -> WheelSoilState:
        W, z, slip, fl, ft, c, tq = self._out
        return WheelSoilState(
            normal_force_n=np.array(W),
            sinkage_m=np.array(z),
            slip=np.array(slip),
            traction_n=np.array(fl),
            lateral_n=np.array(ft),
            torque_nm=np.array(tq),
            in_contact=np.array(c, dtype=bool),
        )

    def lookup(self, material: int, load_n: float, slip: float) -> tuple[float, ...]:
        """Steady state at (load, slip): (sinkage m, H/W, R/W, T/(W r), contact length m, area m^2, Fb/W)."""
        rows, inv_du = self._consts[material][:2]
        u = math.sqrt(max(load_n, 0.0)) * inv_du
        iu = min(int(u), N_LOAD - 2)
        fu = min(u - iu, 1.0)
        v = (min(max(slip, -1.0), 1.0) + 1.0) * 0.5 * (N_SLIP - 1)
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

    def sinkage_m(self, normal_force_n: float, material: int, slip: float) -> float:
        """Steady-state sinkage under ``normal_force_n`` at ``slip`` (step 2)."""
        return self.lookup(material, normal_force_n, slip)[0]

    def evaluate(self, inputs: list[float], material: list[int], dt_s: float) -> list[float]:
        """Soil forces and torques: a flat list ``[fx, fy, fz, T] * n_wheels`` (world-frame force on the wheel at
        the contact point, soil torque resisting the wheel's spin about its axle).

        ``inputs`` is one flat list in the sensor layout of ``models/mer/rover.xml``: per wheel
        ``[found, Fx, Fy, Fz, px, py, pz]`` (the wheel's contact force *on the ground*, zero when not in contact, and
        the contact point), then the wheel-centre velocities (3 per wheel), the rolling directions (3 per wheel)
        and the spin rates (1 per wheel). ``material`` is the soil index per wheel. Build it with
        :func:`pack_inputs` outside the hot loop.
        """
        r = self.radius_m
        nw = self.n_wheels
        out_W, out_z, out_slip, out_fl, out_ft, out_c, out_tq = self._out
        out = [0.0] * (4 * nw)
        exp, sqrt = math.exp, math.sqrt
        alpha = dt_s / (_VEL_FILTER_S + dt_s)
        lookup = self.lookup
        axles = self.axles
        for w in range(nw):
            c = 7 * w
            nx, ny, nz = -inputs[c + 1], -inputs[c + 2], -inputs[c + 3]
            W = sqrt(nx * nx + ny * ny + nz * nz)
            if W < 1e-6:
                # Lifted off (a bounce): the sheared soil stays where it is and is only renewed as the wheel
                # advances over it (no source without contact); resetting it would lose the mobilised thrust
                # at every bounce, and bounces are more frequent the faster the rover drives.
                self._lift_off(w, inputs, dt_s, alpha)
                out_W[w] = out_z[w] = out_fl[w] = out_ft[w] = out_c[w] = out_tq[w] = 0.0
                out_slip[w] = math.nan
                continue
            nx, ny, nz = nx / W, ny / W, nz / W
            k = 7 * nw + 3 * w
            h = k + 3 * nw
            hx, hy, hz = inputs[h], inputs[h + 1], inputs[h + 2]
            hn = hx * nx + hy * ny + hz * nz
            lx, ly, lz = hx - hn * nx, hy - hn * ny, hz - hn * nz
            ln = sqrt(lx * lx + ly * ly + lz * lz)
            lx, ly, lz = lx / ln, ly / ln, lz / ln
            tx, ty, tz = ny * lz - nz * ly, nz * lx - nx * lz, nx * ly - ny * lx
            vx_w, vy_w, vz_w = inputs[k], inputs[k + 1], inputs[k + 2]
            v_x = vx_w * lx + vy_w * ly + vz_w * lz
            v_y = vx_w * tx + vy_w * ty + vz_w * tz
            v_rim = inputs[13 * nw + w] * r
            mat = material[w]
            _, _, tan_phi, coh, K, Ky, n0, n1 = self._consts[mat]
            # step 1: shear states, renewed by the net advance over the soil
            vf = self._vf[w]
            vf[0] += alpha * (v_rim - vf[0])
            vf[1] += alpha * (v_x - vf[1])
            vf[2] += alpha * (v_y - vf[2])
            V = max(abs(vf[0]), abs(vf[1]), abs(vf[2]))
            L = self._patch[w]
            a = V / L
            if a * dt_s > 1e-9:
                decay = exp(-a * dt_s)
                gain = (1.0 - decay) / a
            else:
                decay, gain = 1.0, dt_s
            jx0, jy0 = self._jx[w], self._jy[w]
            jx = min(max(jx0 * decay + (v_rim - v_x) * gain, -L), L)
            jy = min(max(jy0 * decay - v_y * gain, -L), L)
            self._jx[w], self._jy[w] = jx, jy
            i_m = jx / L
            # step 2: the steady-state stresses at the mobilised slip
            z, hn_, rn, tn, Lp, A, fbn = lookup(mat, W, i_m)
            self._patch[w] = Lp
            lat = abs(jy) / Lp
            if lat > abs(i_m):  # lateral sinkage
                z = lookup(mat, W, lat)[0]
            # step 3: compaction resistance as a reaction, reduced in an earlier rut
            bow = min(max(self._bow[w] + v_x * dt_s, -BOW_M), BOW_M)
            self._bow[w] = bow
            zp = self.presink_m[w]
            # Bekker: compaction resistance is the work of compacting to z, b k z^(n+1) / (n+1); in a rut already
            # compacted to z_p only the part from z_p to z is new (Bekker 1969; Wong 2008, multipass)
            fresh = 1.0 - (zp / z) ** (1.0 + n0 + n1 * abs(i_m)) if z > zp else 0.0
            f_long = W * (hn_ - rn * fresh * bow / BOW_M)
            # step 4: lateral shear with its own modulus, mean mobilisation over the patch, plus side-wall bulldozing
            f_max = coh * A + W * tan_phi
            q = abs(jy) / Ky
            mob = 1.0 - (1.0 - exp(-q)) / q if q > 1e-6 else 0.5 * q
            f_lat = mob * f_max * (1.0 if jy >= 0 else -1.0)
            f_t = sqrt(W * W * hn_ * hn_ + f_lat * f_lat)
            if f_t > f_max:  # longitudinal and lateral shear share the strength
                f_lat *= f_max / f_t
            f_lat += mob * W * fbn * (1.0 if jy >= 0 else -1.0)
            # step 5: damping of the shear springs (LuGre sigma_1), zero at steady state
            sigma1 = _BRISTLE_DAMPING_RATIO * 2.0 * sqrt(f_max / (2.0 * K) * self.mass_share_kg)
            f_long += sigma1 * (jx - jx0) / dt_s
            f_lat += sigma1 * (K / Ky) * (jy - jy0) / dt_s
            f_cap = f_max + W * fbn + W * rn
            f_t = sqrt(f_long * f_long + f_lat * f_lat)
            if f_t > f_cap:
                f_long, f_lat = f_long * f_cap / f_t, f_lat * f_cap / f_t
            torque = W * r * tn
            o = 4 * w
            out[o] = f_long * lx + f_lat * tx
            out[o + 1] = f_long * ly + f_lat * ty
            out[o + 2] = f_long * lz + f_lat * tz
            out[o + 3] = torque
            axles[w] = (tx, ty, tz)
            out_W[w], out_z[w], out_fl[w], out_ft[w], out_c[w], out_tq[w] = W, z, f_long, f_lat, 1.0, torque
            out_slip[w] = (v_rim - v_x) / v_rim if abs(v_rim) > _ROLLING_EPS_M_S else math.nan
        return out

    def _lift_off(self, w: int, inputs: list[float], dt_s: float, alpha: float) -> None:
        """Shear states of wheel ``w`` while it is out of contact: renewed by its advance, no source."""
        nw = self.n_wheels
        k = 7 * nw + 3 * w
        h = k + 3 * nw
        vx_w, vy_w = inputs[k], inputs[k + 1]
        hx, hy = inputs[h], inputs[h + 1]
        hn = math.hypot(hx, hy) or 1.0
        v_x = (vx_w * hx + vy_w * hy) / hn
        v_y = (-vx_w * hy + vy_w * hx) / hn
        vf = self._vf[w]
        vf[0] += alpha * (inputs[13 * nw + w] * self.radius_m - vf[0])
        vf[1] += alpha * (v_x - vf[1])
        vf[2] += alpha * (v_y - vf[2])
        decay = math.exp(-max(abs(vf[0]), abs(vf[1]), abs(vf[2])) / self._patch[w] * dt_s)
        self._jx[w] *= decay
        self._jy[w] *= decay
