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
per operation on tiny arrays) would cost 5-10x the MuJoCo step itself, and a plain-float Python loop cost about
90 us a step (three quarters of the MuJoCo step). The arithmetic is therefore compiled
(:mod:`rover_sim.sim.soil_kernel`, numba, bit-identical to the Python loop it replaced); the state and outputs are
numpy arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rover_sim.sim.soil_kernel import bekker_wheels


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
        # rolling radius r - z: a sunk wheel advances (r - z) per radian, not r, so the wheel odometry
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
        self._consts_arr = np.array(self._consts, dtype=float)  # (materials, 9) for the compiled kernel
        self.reset()

    def reset(self) -> None:
        n = self.n_wheels
        self._jx = np.zeros(n)  # shear displacement state, longitudinal (m)
        self._jy = np.zeros(n)  # lateral
        self._patch = np.full(n, 0.1)
        self._out = np.zeros((6, n))  # W, z, slip, f_long, f_lat, contact

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

        ``inputs`` is one flat list in the sensor layout of ``models/mer/rover.xml``: per wheel
        ``[found, Fx, Fy, Fz, px, py, pz]`` (the wheel's contact force *on the ground*, zero when not in contact,
        and the contact point), then the wheel-centre velocities (3 per wheel), the rolling directions (3 per
        wheel) and the spin rates (1 per wheel). ``material`` is the soil index per wheel. Build it with
        :func:`pack_inputs`. The simulator calls :meth:`evaluate_into` on its sensor array instead.
        """
        forces = np.zeros((self.n_wheels, 3))
        self.evaluate_into(np.asarray(inputs, dtype=float), np.asarray(material, dtype=np.int64), dt_s, forces)
        return forces.ravel().tolist()

    def evaluate_into(self, sd: np.ndarray, material: np.ndarray, dt_s: float, forces: np.ndarray) -> None:
        """:meth:`evaluate` on arrays: ``sd`` the sensor block, ``material`` (n,) int64, forces into (n, 3).
        Steps 1-6 of the module docstring, compiled (:func:`rover_sim.sim.soil_kernel.bekker_wheels`)."""
        bekker_wheels(sd, material, self._consts_arr, self._jx, self._jy, self._patch, self._out, forces, dt_s,
                      self.radius_m, self.sinkage_rolling_radius, self.mass_share_kg)  # fmt: skip


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
