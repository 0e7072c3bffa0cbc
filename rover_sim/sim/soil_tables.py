"""Steady-state stress distribution under the MER wheel (Wong–Reece), tabulated for the per-step soil law.

For a wheel of radius ``r`` and width ``b`` at sinkage ``z`` and slip ``i`` the soil's stresses are integrated over
the contact (Wong & Reece 1967; Wong 2008 ch. 4):

* entry angle ``theta1 = acos(1 - z / r)``; the normal stress peaks at ``theta_m = (a0 + a1 |i|) theta1``;
  the rear (exit) angle is 0 (no elastic rebound of loose sand);
* normal stress (Bekker, with the slip-dependent sinkage exponent of Ding et al. 2011, ``n = n0 + n1 |i|``: the
  wheel excavates and transports soil rearward as it slips, so it sinks deeper; this is the slip-sinkage)::

      sigma(theta) = (k_c / b + k_phi) (r (cos theta_e - cos theta1))^n

  with ``theta_e = theta`` in front of ``theta_m`` and the Wong–Reece mirror behind it;
* shear displacement along the rim ``j(theta) = r_s [a_rim (theta1 - theta) - a_x (sin theta1 - sin theta)]``
  where ``a_rim = rim speed / V`` and ``a_x = hub speed / V`` with ``V`` the larger of the two (so one table covers
  driving ``0 <= i <= 1`` and braking / dragging ``-1 <= i < 0``, ``i = -1`` a locked wheel);
* shear stress along the rim (Mohr–Coulomb strength, mobilised over two deformation scales; :func:`mobilisation`)::

      tau = (c + sigma tan phi) [w (1 - exp(-|j| / K)) + (1 - w)(1 - exp(-|j| / K_2))]

  a fraction ``w`` of the strength is mobilised over the short scale ``K``, the rest over the longer ``K_2``.
  With ``w = 1`` this is Janosi & Hanamoto (1961), the form of every material but SAND here. The lateral shear of
  the law (:mod:`rover_sim.sim.terramechanics_wr`, step 4) keeps Janosi-Hanamoto with its own ``K_y``.

MER wheel terms that a plain rigid wheel lacks, each explicit:

* **grousers** (cleats, height ``h_g``): the soil fails in shear at the grouser tips, so shear acts at the radius
  ``r_s = r + h_g`` (longer shear displacement and lever arm);
* **compliant rim**: MER's flexure-spoked rim flattens under load; modelled as a flat patch of length ``l_f`` behind
  the bottom of the arc at the full sinkage, carrying the Bekker plate pressure ``(k_c / b + k_phi) z^n`` and
  the rim's shear curve, its displacement growing at the slip rate across it. On rock (tiny sinkage) the
  flat patch carries the whole load, which is what gives the wheel its grip on outcrop;
* **bulldozing** (Hegedus 1960 as used by Ishigami et al. 2007): the resistance per unit width of soil pushed by a
  wall sunk to ``z``, ``R_b = D1 (c z + D2 gamma z^2 / 2)`` with ``X_c = 45 deg - phi / 2``,
  ``D1 = cot X_c + tan(X_c + phi)``, ``D2 = cot X_c + cot^2 X_c / cot phi``. It acts on the side wall of a wheel
  sliding sideways (length of the contact chord) and on the front of a braked / dragged wheel (``i < 0``).

Integrals (per wheel): ``W = r b int(sigma cos + tau sin) + W_flat``, thrust ``H = r_s b int(tau cos) + H_flat``,
compaction resistance ``R = r b int(sigma sin)`` (+ front bulldozing when braking), torque ``T = r_s^2 b int(tau)
+ r_s H_flat``. The table is over (load, slip): for each slip the sinkage that carries the load is found by
inverting ``W(z)`` (monotone), and the forces are stored per newton of load.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

GRAVITY_MARS_M_S2 = 3.711
N_LOAD = 33  # table nodes in sqrt(load)
N_SLIP = 81  # table nodes in slip, -1 .. 1
MAX_LOAD_N = 500.0  # beyond this the per-newton forces are taken from the last node
N_THETA = 64
N_FLAT = 12
N_SINK = 400


@dataclass(frozen=True)
class WheelParams:
    """The MER wheel as the soil sees it."""

    radius_m: float = 0.125  # 0.25 m diameter (REFERENCE.md section 1)
    width_m: float = 0.16
    grouser_height_m: float = 0.005  # cleats on the rim (assumed 5 mm)
    flat_patch_m: float = 0.04  # flattened length of the flexure rim under about one sixth of the rover's weight


@dataclass(frozen=True)
class SoilParams:
    """Terramechanics parameters of one ground material (SI units)."""

    name: str
    cohesion_pa: float  # c
    friction_angle_deg: float  # phi
    shear_modulus_m: float  # Janosi-Hanamoto K, longitudinal (the short scale of a two-scale curve)
    lateral_shear_modulus_m: float  # K_y (Ishigami et al. 2007: its own shear deformation modulus)
    k_c: float  # Bekker cohesive modulus
    k_phi: float  # Bekker frictional modulus
    n0: float  # sinkage exponent at zero slip
    n1: float  # growth of the sinkage exponent with |slip| (Ding et al. 2011)
    a0: float  # Wong-Reece: theta_m = (a0 + a1 |i|) theta1
    a1: float
    density_kg_m3: float
    deformable: bool = True  # False: bedrock / rock, the terrain never changes
    # Two-scale longitudinal shear curve (`mobilisation`): the fraction w of the strength mobilised over K, the rest
    # over K_2 = slow_shear_ratio K. w = 1: Janosi-Hanamoto. The lateral curve is Janosi-Hanamoto with K_y.
    fast_shear_fraction: float = 1.0
    slow_shear_ratio: float = 1.0

    def __post_init__(self) -> None:
        if not 0.0 < self.fast_shear_fraction <= 1.0:
            raise ValueError(
                f"soil {self.name!r}: fast_shear_fraction must be in (0, 1], not {self.fast_shear_fraction}"
            )
        if self.slow_shear_ratio < 1.0:
            raise ValueError(f"soil {self.name!r}: slow_shear_ratio must be >= 1, not {self.slow_shear_ratio}")

    @property
    def initial_shear_modulus_m(self) -> float:
        """The deformation scale of the curve's initial slope: ``d(tau / tau_max)/dj = 1 / K_0`` at ``j = 0``."""
        w = self.fast_shear_fraction
        if w >= 1.0:
            return self.shear_modulus_m
        return self.shear_modulus_m / (w + (1.0 - w) / self.slow_shear_ratio)


def mobilisation(j_abs: np.ndarray, soil: SoilParams) -> np.ndarray:
    """Fraction of the shear strength mobilised along the rim at shear displacement ``|j|``:
    ``w (1 - exp(-|j| / K)) + (1 - w)(1 - exp(-|j| / K_2))`` with ``w = soil.fast_shear_fraction``,
    ``K = soil.shear_modulus_m``, ``K_2 = soil.slow_shear_ratio K``; ``w = 1`` is Janosi & Hanamoto (1961) exactly.

    Two deformation scales in one monotone curve. Janosi-Hanamoto's single exponential is Wong's curve for loose
    sand (Wong 2010, *Terramechanics and Off-Road Vehicle Engineering*, sec. 2.4); Wong's curves for other soils
    already use two displacement parameters (a hump over ``K_w`` then a residual, Wong 1983), and Bekker's (1956)
    shear equation is a combination of two exponentials. This sum of two Janosi-Hanamoto terms with positive
    weights is a MODELLING CHOICE (no published calibration of this exact form for sand was found): a grousered
    wheel engages part of the soil strength within a few millimetres (soil locked between the grousers and the
    sheared layer under them), the rest only as the failure zone under the slipping wheel grows with the
    displacement. It is the rolling wheel's curve: sideways, the law keeps Ishigami et al.'s (2007) own
    Janosi-Hanamoto curve with ``K_y``.
    """
    k_m = soil.shear_modulus_m
    w = soil.fast_shear_fraction
    fast = 1.0 - np.exp(-j_abs / k_m)
    if w >= 1.0:
        return fast
    return w * fast + (1.0 - w) * (1.0 - np.exp(-j_abs / (soil.slow_shear_ratio * k_m)))


def bulldozing_per_width(soil: SoilParams, z: np.ndarray | float) -> np.ndarray | float:
    """Hegedus bulldozing resistance per unit wall length of a wall sunk ``z`` into the soil, N/m."""
    phi = math.radians(soil.friction_angle_deg)
    xc = math.radians(45.0) - phi / 2.0
    cot = 1.0 / math.tan(xc)
    d1 = cot + math.tan(xc + phi)
    d2 = cot + cot * cot * math.tan(phi)
    gamma = soil.density_kg_m3 * GRAVITY_MARS_M_S2
    return d1 * (soil.cohesion_pa * z + 0.5 * d2 * gamma * z * z)


def _kinematics(slip: float) -> tuple[float, float]:
    """(rim speed / V, hub speed / V) for the slip ratio (i >= 0 driving, i < 0 braking; i = -1 locked)."""
    return (1.0, 1.0 - slip) if slip >= 0 else (1.0 + slip, 1.0)


def integrate(
    soil: SoilParams, wheel: WheelParams, z: np.ndarray, slip: float, front_bulldozing: bool = True
) -> dict[str, np.ndarray]:
    """Load, thrust, resistance, torque, contact length and area for sinkages ``z`` (array) at slip ``slip``."""
    r, b = wheel.radius_m, wheel.width_m
    rs = r + wheel.grouser_height_m
    tan_phi = math.tan(math.radians(soil.friction_angle_deg))
    c = soil.cohesion_pa
    k = soil.k_c / b + soil.k_phi
    n = soil.n0 + soil.n1 * abs(slip)
    a_rim, a_x = _kinematics(slip)
    z = np.asarray(z, dtype=float)[:, None]
    th1 = np.arccos(np.clip(1.0 - z / r, -1.0, 1.0))
    thm = (soil.a0 + soil.a1 * abs(slip)) * th1
    t = np.linspace(0.0, 1.0, N_THETA)[None, :]
    th = th1 * t
    front = th >= thm
    th_e = np.where(front, th, th1 - th / np.maximum(thm, 1e-12) * (th1 - thm))
    sigma = k * np.maximum(r * (np.cos(th_e) - np.cos(th1)), 0.0) ** n
    j = rs * (a_rim * (th1 - th) - a_x * (np.sin(th1) - np.sin(th)))
    tau = (c + sigma * tan_phi) * mobilisation(np.abs(j), soil) * np.sign(j)
    dth = th1[:, 0] / (N_THETA - 1)

    def trap(y: np.ndarray) -> np.ndarray:
        return (y.sum(axis=1) - 0.5 * (y[:, 0] + y[:, -1])) * dth

    W = r * b * trap(sigma * np.cos(th)) + rs * b * trap(tau * np.sin(th))
    H = rs * b * trap(tau * np.cos(th))
    R = r * b * trap(sigma * np.sin(th))
    T = rs * rs * b * trap(tau)
    lf = wheel.flat_patch_m
    if lf > 0:  # compliant rim: flat patch at the full sinkage
        zc = z[:, 0]
        sig_f = k * zc**n
        j0 = rs * (a_rim * th1[:, 0] - a_x * np.sin(th1[:, 0]))
        x = np.linspace(0.0, lf, N_FLAT)[None, :]
        jf = j0[:, None] + (a_rim - a_x) * x
        mob = (mobilisation(np.abs(jf), soil) * np.sign(jf)).mean(axis=1)
        h_f = b * lf * (c + sig_f * tan_phi) * mob
        W = W + b * lf * sig_f
        H = H + h_f
        T = T + rs * h_f
    zc = z[:, 0]
    if front_bulldozing and slip < 0:  # a braked / dragged wheel pushes soil ahead of it
        R = R + (-slip) * b * bulldozing_per_width(soil, zc)
    length = r * th1[:, 0] + lf
    return {"W": W, "H": H, "R": R, "T": T, "L": length, "A": b * length}


def sinkage_grid(soil: SoilParams) -> np.ndarray:
    """Sinkages over which ``W(z)`` is evaluated before inversion (log-spaced: rock sinks microns, sand cm)."""
    lo = 1e-9 if not soil.deformable else 1e-6
    return np.geomspace(lo, 0.12, N_SINK)


def build_table(soil: SoilParams, wheel: WheelParams) -> tuple[list[tuple[float, ...]], float]:
    """Flat table ``rows[i_slip * N_LOAD + i_load] = (z, H/W, R/W, T/(W r), L, A, Fb/W)`` and ``MAX_LOAD_N``.

    Load nodes are uniform in ``sqrt(W / MAX_LOAD_N)``; slip nodes uniform in ``[-1, 1]``. ``Fb`` is the side-wall
    bulldozing force on the contact chord at the full lateral mobilisation.
    """
    loads = (np.linspace(0.0, 1.0, N_LOAD) ** 2) * MAX_LOAD_N
    loads[0] = 1e-3 * MAX_LOAD_N / (N_LOAD - 1) ** 2  # avoid 0/0 at the first node
    zs = sinkage_grid(soil)
    rows: list[tuple[float, ...]] = []
    for slip in np.linspace(-1.0, 1.0, N_SLIP):
        q = integrate(soil, wheel, zs, float(slip))
        W = q["W"]
        order = np.argsort(W)
        Wz, zz = W[order], zs[order]
        z_at = np.interp(loads, Wz, zz)
        qq = integrate(soil, wheel, z_at, float(slip))
        fb = bulldozing_per_width(soil, z_at) * 2.0 * np.sqrt(np.maximum(2 * wheel.radius_m * z_at - z_at**2, 0.0))
        for k_ in range(N_LOAD):
            w = max(float(qq["W"][k_]), 1e-12)
            rows.append(
                (
                    float(z_at[k_]),
                    float(qq["H"][k_]) / w,
                    float(qq["R"][k_]) / w,
                    float(qq["T"][k_]) / (w * wheel.radius_m),
                    float(qq["L"][k_]),
                    float(qq["A"][k_]),
                    float(fb[k_]) / w,
                )
            )
    return rows, MAX_LOAD_N
