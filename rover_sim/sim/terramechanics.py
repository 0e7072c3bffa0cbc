"""Wheel–soil law: Bekker sinkage, Mohr–Coulomb shear strength, Janosi–Hanamoto shear mobilisation.

MuJoCo supplies only the *normal* wheel load (wheel contacts are frictionless, ``condim=1``); every tangential
force between a wheel and the ground comes from this module, evaluated for all six wheels at once each physics
step. Slip is therefore an outcome of the soil law, the load on each wheel and the slope — nothing is scripted.

Per wheel (vectorised over the six):

1. **Sinkage** (Bekker 1969, rigid wheel, Wong 2008 eq. 2.39)::

       z0 = (3 W / ((3 - n) (k_c + b k_phi) sqrt(D)))^(2 / (2n + 1))

   grown with slip (slip-sinkage, Lyasko 2010): ``z = z0 (1 + slip_sinkage * max(i, 0))``.
2. **Contact patch** length ``L = r acos(1 - z / r) + tread_length_m`` (the arc in the soil plus the flat patch of
   MER's compliant flexure wheel and grousers), area ``A = b L``.
3. **Shear strength** (Mohr–Coulomb): ``F_max = c A + W tan(phi)``.
4. **Shear displacement** ``j`` (a 2-vector: longitudinal, lateral) is a state. Under a rolling wheel the soil
   element entering the patch has ``j = 0`` and leaving it has ``j = i L`` (Janosi & Hanamoto 1961; Wong & Reece
   1967): we integrate ``dj/dt = v_slip - (V / L) j``, whose steady state is
   ``j = i L`` for slip ratio ``i = (r omega - v_x) / (r omega)`` and lateral ``j_y = -v_y L / V``. Here
   ``V = |r omega|``: fresh soil enters the patch only as the wheel rolls, so a held wheel keeps its mobilised
   shear (a parked rover is held by the soil acting as a stiff spring instead of creeping) and a locked wheel
   dragged along mobilises the full strength (Coulomb-like sliding).
5. **Shear mobilisation** averaged over the patch (Janosi–Hanamoto integrated along ``x``)::

       F = F_max * (1 - (K / j) (1 - exp(-j / K)))   with j = |j|, direction of j

6. **Compaction (rolling) resistance** (Bekker): ``R_c = b (k_c / b + k_phi) z^(n+1) / (n + 1)`` opposing the
   wheel's motion.

The force is returned in the world frame, applied at the contact point.

Implementation note: the law runs every physics step for six wheels, where numpy's per-call overhead (about 1 us
per operation on tiny arrays) would cost 5-10x the MuJoCo step itself. :meth:`WheelSoilLaw.evaluate` is therefore a
plain-float loop over the wheels on Python lists (about 25 us for six wheels here); the state and outputs are
exposed as numpy arrays for logging.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SoilParams:
    """Terramechanics parameters of one ground material (SI units)."""

    name: str
    cohesion_pa: float  # c
    friction_angle_deg: float  # phi
    shear_modulus_m: float  # Janosi-Hanamoto K
    k_c: float  # Bekker cohesive modulus, N/m^(n+1)
    k_phi: float  # Bekker frictional modulus, N/m^(n+2)
    n: float  # Bekker sinkage exponent
    slip_sinkage: float  # dimensionless growth of sinkage with slip
    tread_length_m: float  # flat-patch length of the compliant wheel + grousers


# Loose Martian sand. Bekker and Mohr-Coulomb values from the ranges in REFERENCE.md section 2 (Wong 2008 Table 2.3
# dry sand; Sullivan et al. 2011 and Arvidson et al. 2011 for MER-era regolith: c 0.2-1 kPa, phi 28-37 deg,
# K 1-2.5 cm). Calibrated *within* those ranges against the published MER slip (about 50 % at 17-20 deg):
# see models/mer/README.md and `rover-sim bench slip`.
SAND = SoilParams(
    name="sand",
    cohesion_pa=1000.0,
    friction_angle_deg=37.0,
    shear_modulus_m=0.015,
    k_c=1.4e4,
    k_phi=1.5e6,
    n=0.8,
    slip_sinkage=4.0,
    tread_length_m=0.10,
)

# Bedrock outcrop (Burns formation sandstone): no sinkage, high friction of aluminium grousers on rock, and a
# short shear-mobilisation length (elastic tread deflection, about 1.5 mm).
BEDROCK = SoilParams(
    name="bedrock",
    cohesion_pa=0.0,
    friction_angle_deg=42.0,
    shear_modulus_m=0.0015,
    k_c=0.0,
    k_phi=1.0e9,
    n=1.0,
    slip_sinkage=0.0,
    tread_length_m=0.05,
)

# Thin sand over rock / gravel (Spirit's Columbia Hills soils): between the two.
MIXED = SoilParams(
    name="mixed",
    cohesion_pa=500.0,
    friction_angle_deg=36.0,
    shear_modulus_m=0.006,
    k_c=5.0e3,
    k_phi=2.3e6,
    n=1.0,
    slip_sinkage=0.5,
    tread_length_m=0.05,
)

# Index order matches terrains.Material (SAND=0, BEDROCK=1, MIXED=2); rocks are treated as BEDROCK.
MATERIALS: tuple[SoilParams, ...] = (SAND, BEDROCK, MIXED)


@dataclass
class WheelSoilState:
    """Per-wheel outputs of the last evaluation (ground truth for logging/evaluation)."""

    normal_force_n: np.ndarray  # (6,)
    sinkage_m: np.ndarray  # (6,)
    slip: np.ndarray  # (6,) longitudinal slip ratio, NaN where not rolling or not in contact
    traction_n: np.ndarray  # (6,) longitudinal force (wheel frame), net of compaction resistance
    lateral_n: np.ndarray  # (6,) lateral force
    in_contact: np.ndarray  # (6,) bool


_ROLLING_EPS_M_S = 1e-4  # rim speeds below this count as "not rolling" for the slip ratio
_RC_SMOOTHING_M_S = 0.005  # compaction resistance fades in over this hub speed (tanh), no chatter at rest
_J_CAP_K = 50.0  # shear displacement is capped at this many K (the law is saturated there)
_BRISTLE_DAMPING_RATIO = 0.7  # damping ratio of the shear spring (initial stiffness F_max / 2K) per wheel


class WheelSoilLaw:
    """Wheel–soil force law for ``n_wheels`` wheels of radius ``radius_m`` and width ``width_m``.

    ``materials[k]`` is the soil of material index ``k`` (``terrains.Material`` order).
    """

    def __init__(
        self,
        radius_m: float = 0.125,
        width_m: float = 0.16,
        n_wheels: int = 6,
        materials: tuple[SoilParams, ...] = MATERIALS,
        mass_share_kg: float = 29.0,
    ) -> None:
        self.radius_m = radius_m
        # rolling radius r - z (issue #16): a sunk wheel advances (r - z) per radian, not r, so the wheel odometry
        # (nominal r) over-counts by z / r (about 5 % in the sim's sand). Off by default (today's law, on which the
        # slip anchors were calibrated); [sensors.odometry] sinkage_rolling_radius = true turns it on.
        self.sinkage_rolling_radius = False
        self.mass_share_kg = mass_share_kg  # vehicle mass per wheel, for the bristle damping
        self.width_m = width_m
        self.n_wheels = n_wheels
        self.materials = materials
        # per-material constants, precomputed once: (k_eq, exponent, tan_phi, c*b, K, slip_sinkage, tread, n,
        # b*(k_c/b + k_phi))
        self._consts = []
        for m in materials:
            k_eq = m.k_c + width_m * m.k_phi
            sink_coef = 3.0 / ((3.0 - m.n) * k_eq * math.sqrt(2.0 * radius_m))
            self._consts.append(
                (
                    sink_coef,
                    2.0 / (2.0 * m.n + 1.0),
                    math.tan(math.radians(m.friction_angle_deg)),
                    m.cohesion_pa * width_m,
                    m.shear_modulus_m,
                    m.slip_sinkage,
                    m.tread_length_m,
                    m.n,
                    width_m * (m.k_c / width_m + m.k_phi) / (m.n + 1.0),
                )
            )
        self.reset()

    def reset(self) -> None:
        n = self.n_wheels
        self._jx = [0.0] * n  # shear displacement state, longitudinal (m)
        self._jy = [0.0] * n  # lateral
        self._patch = [0.1] * n
        self._out = [[0.0] * n for _ in range(6)]  # W, z, slip, f_long, f_lat, contact

    @property
    def j_m(self) -> np.ndarray:
        """(n, 2) shear displacement state (longitudinal, lateral), metres."""
        return np.array([self._jx, self._jy]).T

    @property
    def state(self) -> WheelSoilState:
        W, z, slip, fl, ft, c = self._out
        return WheelSoilState(
            normal_force_n=np.array(W),
            sinkage_m=np.array(z),
            slip=np.array(slip),
            traction_n=np.array(fl),
            lateral_n=np.array(ft),
            in_contact=np.array(c, dtype=bool),
        )

    def sinkage_m(self, normal_force_n: float, material: int, slip: float) -> float:
        """Bekker rigid-wheel sinkage grown with positive slip (step 1)."""
        sink_coef, expo, _, _, _, ss, _, _, _ = self._consts[material]
        z0 = (sink_coef * max(normal_force_n, 0.0)) ** expo
        return z0 * (1.0 + ss * min(max(slip, 0.0), 1.0))

    def evaluate(self, inputs: list[float], material: list[int], dt_s: float) -> list[float]:
        """Tangential wheel–soil forces in the world frame: a flat list ``[fx, fy, fz] * n_wheels``.

        ``inputs`` is one flat list in the sensor layout of ``models/mer/rover.xml`` (so the simulator reads it
        in one slice): per wheel ``[found, Fx, Fy, Fz, px, py, pz]`` (the wheel's contact force *on the ground*,
        zero when not in contact, and the contact point), then the wheel-centre velocities (3 per wheel), the
        rolling directions (3 per wheel) and the spin rates (1 per wheel). ``material`` is the soil index per wheel.
        Build it with :func:`pack_inputs` outside the hot loop.
        """
        r = self.radius_m
        nw = self.n_wheels
        out_W, out_z, out_slip, out_fl, out_ft, out_c = self._out
        forces = [0.0] * (3 * nw)
        exp, sqrt, acos = math.exp, math.sqrt, math.acos
        for w in range(self.n_wheels):
            c = 7 * w
            # the ground's reaction on the wheel is minus the wheel's force on the ground
            nx, ny, nz = -inputs[c + 1], -inputs[c + 2], -inputs[c + 3]
            W = sqrt(nx * nx + ny * ny + nz * nz)
            if W < 1e-6:
                self._jx[w] = self._jy[w] = 0.0
                out_W[w] = out_z[w] = out_fl[w] = out_ft[w] = out_c[w] = 0.0
                out_slip[w] = math.nan
                continue
            nx, ny, nz = nx / W, ny / W, nz / W
            # contact tangent frame: heading projected on the contact plane, lateral = n x long
            k = 7 * nw + 3 * w  # hub velocity block; headings follow 3 * nw later
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
            sink_coef, expo, tan_phi, cb, K, ss, tread, n, rc_coef = self._consts[material[w]]
            # steps 1-3: sinkage (slip-sinkage from the slip the soil has mobilised, j/L: the state's steady state
            # is j = i L, a physically lagged, noise-free slip), patch length, shear strength
            i_mob = min(max(self._jx[w] / self._patch[w], 0.0), 1.0)
            z = (sink_coef * W) ** expo * (1.0 + ss * i_mob)
            v_rim = inputs[13 * nw + w] * (r - min(z, 0.5 * r) if self.sinkage_rolling_radius else r)
            L = r * acos(max(1.0 - z / r, -1.0)) + tread
            self._patch[w] = L
            f_max = cb * L + W * tan_phi
            # step 4: shear displacement, exact integration of dj/dt = v_slip - (V/L) j. Fresh soil enters the
            # patch only as the wheel *rolls* (V = |r omega|): a held wheel keeps its mobilised shear (a parked
            # rover does not creep) and a locked, dragged wheel mobilises the full strength F_max.
            a = abs(v_rim) / L
            if a * dt_s > 1e-9:
                decay = exp(-a * dt_s)
                gain = (1.0 - decay) / a
            else:
                decay, gain = 1.0, dt_s
            jx0, jy0 = self._jx[w], self._jy[w]
            jx = jx0 * decay + (v_rim - v_x) * gain
            jy = jy0 * decay - v_y * gain
            j_cap = _J_CAP_K * K  # beyond this the mobilised shear is F_max to 1 part in 50
            jx, jy = min(max(jx, -j_cap), j_cap), min(max(jy, -j_cap), j_cap)
            self._jx[w], self._jy[w] = jx, jy
            # step 5: Janosi-Hanamoto mobilisation averaged over the patch, along the shear displacement
            j = sqrt(jx * jx + jy * jy)
            if j > 1e-12:
                x = j / K
                mob = 1.0 - (1.0 - exp(-x)) / x if x > 1e-6 else 0.5 * x
                s = f_max * mob / j
                f_long, f_lat = s * jx, s * jy
            else:
                f_long = f_lat = 0.0
            # bristle damping (LuGre sigma_1): damps the soil-spring / suspension modes that a stiff, explicitly
            # integrated shear spring would excite; critically damped for a sixth of the rover's mass
            sigma1 = _BRISTLE_DAMPING_RATIO * 2.0 * sqrt(f_max / (2.0 * K) * self.mass_share_kg)
            f_long += sigma1 * (jx - jx0) / dt_s
            f_lat += sigma1 * (jy - jy0) / dt_s
            f_t = sqrt(f_long * f_long + f_lat * f_lat)
            if f_t > f_max:  # the soil cannot carry more than its shear strength
                f_long, f_lat = f_long * f_max / f_t, f_lat * f_max / f_t
            # step 6: compaction resistance, bounded (deeper sinkage would be bulldozing, not modelled)
            r_c = min(rc_coef * z ** (n + 1.0), 0.5 * W)
            f_long -= r_c * math.tanh(v_x / _RC_SMOOTHING_M_S)
            k = 3 * w
            forces[k] = f_long * lx + f_lat * tx
            forces[k + 1] = f_long * ly + f_lat * ty
            forces[k + 2] = f_long * lz + f_lat * tz
            out_W[w], out_z[w], out_fl[w], out_ft[w], out_c[w] = W, z, f_long, f_lat, 1.0
            out_slip[w] = (v_rim - v_x) / v_rim if abs(v_rim) > _ROLLING_EPS_M_S else math.nan
        return forces


def pack_inputs(
    normal_force_w: np.ndarray,
    contact_pos_w: np.ndarray,
    hub_vel_w: np.ndarray,
    heading_w: np.ndarray,
    wheel_rate_rad_s: np.ndarray,
) -> list[float]:
    """Build :meth:`WheelSoilLaw.evaluate`'s flat input list from (n, 3) arrays (ground reaction on each wheel,
    contact points, hub velocities, headings) and (n,) spin rates. For tests and offline analysis."""
    normal_force_w = np.asarray(normal_force_w, dtype=float)
    found = (np.linalg.norm(normal_force_w, axis=1) > 0).astype(float)[:, None]
    contact = np.hstack([found, -normal_force_w, np.asarray(contact_pos_w, dtype=float)])
    return np.concatenate(
        [contact.ravel(), np.ravel(hub_vel_w), np.ravel(heading_w), np.ravel(wheel_rate_rad_s)]
    ).tolist()
