"""Steady-state stress distribution under the MER wheel (Wong–Reece), tabulated for the per-step soil law.

For a wheel of radius ``r`` and width ``b`` at sinkage ``z`` and slip ``i`` the soil's stresses are integrated over
the contact (Wong & Reece 1967; Wong 2008 ch. 4):

* entry angle ``theta1 = acos(1 - z / r)``; the normal stress peaks at ``theta_m = (a0 + a1 |i|) theta1``;
  the rear (exit) angle ``theta2 = -acos(1 - lambda z / r)`` where the soil rebounds by a fraction ``lambda`` of
  the sinkage behind the wheel (Wong 2008, *Theory of Ground Vehicles* 4th ed., ch. 4: rebound and the rear
  contact of a rigid wheel; ``lambda = 0``, no rebound, for the planetary soils here), and the rear region
  ``theta2 .. theta_m`` carries the Wong–Reece mirrored stress;
* normal stress (Bekker, with the slip-dependent sinkage exponent of Ding et al. 2011, ``n = n0 + n1 |i|``: the
  wheel excavates and transports soil rearward as it slips, so it sinks deeper; this is the slip-sinkage, for
  both signs of slip: a braked or dragged wheel (``i < 0``) shears the soil forward and sinks too, and its
  shear then pulls it down, ``tau sin(theta) < 0`` in the load integral: Wong & Reece 1967, part II)::

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

* **grousers** (cleats, height ``h_g``): the soil locked between closely spaced grousers fails in shear at their
  tips, so shear acts soil on soil at the radius ``r_s = r + h_g`` (longer shear displacement and lever arm;
  Ishigami et al. 2007, Jia et al. 2012). A **smooth rim** (``h_g = 0``) instead slides on the soil where it drives
  it rearward (``i > 0``): the interface's friction ``tan(delta) = f tan(phi)`` (and adhesion ``f c``) with ``f`` the
  soil's skin-friction ratio on a smooth surface (``SoilParams.smooth_rim_friction``; Potyondy 1961: about 0.5-0.8
  for smooth to rough steel on dry sand), and it carries that fraction of the soil a grouser would carry away,
  so its slip-sinkage grows with ``f |i|``. Braked or dragged (``i < 0``), the soil ahead of the rim moves with it
  (Wong & Reece 1967, part II) and both rims shear soil on soil;
* **compliant rim**: MER's flexure-spoked rim flattens under load; modelled as a flat patch of length ``l_f`` behind
  the bottom of the arc at the full sinkage, carrying the Bekker plate pressure ``(k_c / b + k_phi) z^n`` and
  the rim's shear curve, its displacement growing at the slip rate across it. On rock (tiny sinkage) the
  flat patch carries the whole load, which is what gives the wheel its grip on outcrop;
* **bulldozing** (Hegedus 1960 as used by Ishigami et al. 2007; Wong 2008 ch. 4): the resistance per unit width
  of soil pushed by a wall sunk to ``z``, ``R_b = D1 (c z + D2 gamma z^2 / 2)`` with ``X_c = 45 deg - phi / 2``,
  ``D1 = cot X_c + tan(X_c + phi)``, ``D2 = cot X_c + cot^2 X_c / cot phi`` and ``gamma`` the soil's unit weight
  (its density times the gravity it lies in: Mars for the rover's soils, Earth for a laboratory bin). It acts on
  the front of a braked / dragged wheel, the berm it pushes ahead, in proportion to the share of its advance the
  rim does not roll over (``-i``, ``i < 0``: a locked wheel pushes all of it); sideways, on the submerged side face
  of the wheel (:func:`side_wall_n`, applied by the law).

Integrals (per wheel): ``W = r b int(sigma cos + tau sin) + W_flat``, thrust ``H = r_s b int(tau cos) + H_flat``,
compaction resistance ``R = r b int(sigma sin)`` (+ front bulldozing when braking), torque ``T = r_s^2 b int(tau)
+ r_s H_flat``. The table is over (load, slip): for each slip the sinkage that carries the load is the first
(shallowest) one at which ``W(z)`` reaches it (``W`` need not be monotone where a dragged wheel's shear pulls it
down), and the forces are stored per newton of load. Its last column is the sinkage of the same wheel rolling,
its soil sheared by the slip magnitude ``s = |slip| LAT_SLIP_MAX`` (:func:`lateral_sinkage`), from which the law
takes the extra sinkage of a wheel that also slides sideways.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

GRAVITY_MARS_M_S2 = 3.711
N_LOAD = 33  # table nodes in sqrt(load)
N_SLIP = 81  # table nodes in slip, -1 .. 1
MAX_LOAD_N = 500.0  # beyond this the per-newton forces are taken from the last node
N_THETA = 64
N_FLAT = 12
N_SINK = 400
LAT_SLIP_MAX = 2.0  # the lateral-sinkage column covers slip magnitudes (shear displacement / patch) 0 .. 2


@dataclass(frozen=True)
class WheelParams:
    """A wheel as the soil sees it (defaults: the MER wheel). ``radius_m`` is the rim's radius (the base of any
    grousers); ``grouser_height_m = 0`` is a smooth rim. Grousers are taken as closely spaced (soil locked between
    them), so their number does not enter the law; ``grouser_count`` records it where the source gives it."""

    radius_m: float = 0.125  # 0.25 m diameter (REFERENCE.md section 1)
    width_m: float = 0.16
    grouser_height_m: float = 0.005  # cleats on the rim (assumed 5 mm)
    flat_patch_m: float = 0.04  # flattened length of the flexure rim under about one sixth of the rover's weight
    grouser_count: int | None = None  # None: not known (not used by the law)


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
    # The weight of the soil (bulldozing): its density times the gravity it lies in (Mars, or a laboratory on Earth).
    gravity_m_s2: float = GRAVITY_MARS_M_S2
    # Rebound behind the wheel as a fraction of the sinkage: the rear contact angle (0: no rebound, loose sand).
    rebound_ratio: float = 0.0
    # Skin friction of a smooth rim on this soil: tan(delta) / tan(phi) (Potyondy 1961); 1 = soil on soil.
    smooth_rim_friction: float = 1.0

    def __post_init__(self) -> None:
        if not 0.0 < self.fast_shear_fraction <= 1.0:
            raise ValueError(
                f"soil {self.name!r}: fast_shear_fraction must be in (0, 1], not {self.fast_shear_fraction}"
            )
        if self.slow_shear_ratio < 1.0:
            raise ValueError(f"soil {self.name!r}: slow_shear_ratio must be >= 1, not {self.slow_shear_ratio}")
        if not 0.0 <= self.rebound_ratio < 1.0:
            raise ValueError(f"soil {self.name!r}: rebound_ratio must be in [0, 1), not {self.rebound_ratio}")
        if not 0.0 < self.smooth_rim_friction <= 1.0:
            raise ValueError(
                f"soil {self.name!r}: smooth_rim_friction must be in (0, 1], not {self.smooth_rim_friction}"
            )

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
    gamma = soil.density_kg_m3 * soil.gravity_m_s2
    return d1 * (soil.cohesion_pa * z + 0.5 * d2 * gamma * z * z)


def hegedus_coefficients(soil: SoilParams) -> tuple[float, float, float]:
    """Hegedus's ``D1``, ``D2`` and the soil's unit weight ``gamma`` (N/m^3), for the compiled side-wall term."""
    phi = math.radians(soil.friction_angle_deg)
    xc = math.radians(45.0) - phi / 2.0
    cot = 1.0 / math.tan(xc)
    return cot + math.tan(xc + phi), cot + cot * cot * math.tan(phi), soil.density_kg_m3 * soil.gravity_m_s2


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
    transport = abs(slip)  # the slip that excavates and carries soil away (slip-sinkage)
    if wheel.grouser_height_m <= 0.0 and slip > 0.0 and soil.smooth_rim_friction < 1.0:
        f = soil.smooth_rim_friction  # a smooth rim driven over the soil slides on it (skin friction)
        tan_phi, c, transport = f * tan_phi, f * c, f * transport
    n = soil.n0 + soil.n1 * transport
    a_rim, a_x = _kinematics(slip)
    z = np.asarray(z, dtype=float)[:, None]
    th1 = np.arccos(np.clip(1.0 - z / r, -1.0, 1.0))
    thm = (soil.a0 + soil.a1 * abs(slip)) * th1
    t = np.linspace(0.0, 1.0, N_THETA)[None, :]
    if soil.rebound_ratio > 0.0:  # rear contact on the rebounded soil (Wong 2008)
        th2 = -np.arccos(np.clip(1.0 - soil.rebound_ratio * z / r, -1.0, 1.0))
        th = th2 + (th1 - th2) * t
        front = th >= thm
        th_e = np.where(front, th, th1 - (th - th2) / np.maximum(thm - th2, 1e-12) * (th1 - thm))
    else:
        th2 = np.zeros_like(th1)
        th = th1 * t
        front = th >= thm
        th_e = np.where(front, th, th1 - th / np.maximum(thm, 1e-12) * (th1 - thm))
    sigma = k * np.maximum(r * (np.cos(th_e) - np.cos(th1)), 0.0) ** n
    j = rs * (a_rim * (th1 - th) - a_x * (np.sin(th1) - np.sin(th)))
    tau = (c + sigma * tan_phi) * mobilisation(np.abs(j), soil) * np.sign(j)
    dth = (th1[:, 0] - th2[:, 0]) / (N_THETA - 1)

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
    length = r * (th1[:, 0] - th2[:, 0]) + lf
    return {"W": W, "H": H, "R": R, "T": T, "L": length, "A": b * length}


def sinkage_grid(soil: SoilParams) -> np.ndarray:
    """Sinkages over which ``W(z)`` is evaluated before inversion (log-spaced: rock sinks microns, sand cm)."""
    lo = 1e-9 if not soil.deformable else 1e-6
    return np.geomspace(lo, 0.12, N_SINK)


def first_sinkage_carrying(loads: np.ndarray, W: np.ndarray, zs: np.ndarray) -> np.ndarray:
    """The shallowest sinkage at which the load integral ``W(zs)`` reaches each of ``loads`` (linear between grid
    nodes). Where ``W`` rises monotonically, as for a driven wheel, this is plain interpolation of ``z(W)``."""
    if np.all(np.diff(W) > 0.0):
        return np.interp(loads, W, zs)
    env = np.maximum.accumulate(W)
    i = np.clip(np.searchsorted(env, loads, side="left"), 1, len(W) - 1)
    w0, w1 = W[i - 1], W[i]
    frac = np.clip((loads - w0) / np.maximum(w1 - w0, 1e-300), 0.0, 1.0)
    return np.where(loads >= env[-1], zs[-1], zs[i - 1] + frac * (zs[i] - zs[i - 1]))


def lateral_sinkage(soil: SoilParams, wheel: WheelParams, loads: np.ndarray, slip: float) -> np.ndarray:
    """Sinkage under ``loads`` of a wheel rolling without longitudinal shear kinematics whose soil is sheared by the
    slip magnitude ``s`` (its shear displacement over the patch length, in any direction): Ding et al.'s
    slip-sinkage exponent ``n = n0 + n1 s``. The law deepens a wheel that also slides sideways by
    ``lateral_sinkage(s_all) - lateral_sinkage(|i|)``, with ``s_all = hypot(i, s_lat)``: the slip-sinkage of a
    soil that does not know in which direction it was sheared (isotropic), beyond what the longitudinal slip alone
    already gives (Ding et al. 2011 measured it along the travel; Ishigami et al. 2007's lateral shear kinematics)."""
    sideways = replace(soil, n0=soil.n0 + soil.n1 * slip, n1=0.0)
    zs = sinkage_grid(soil)
    return first_sinkage_carrying(loads, integrate(sideways, wheel, zs, 0.0)["W"], zs)


def build_table(soil: SoilParams, wheel: WheelParams) -> tuple[list[tuple[float, ...]], float]:
    """Flat table ``rows[i_slip * N_LOAD + i_load] = (z, H/W, R/W, T/(W r), L, A, z_lat)`` and ``MAX_LOAD_N``.

    Load nodes are uniform in ``sqrt(W / MAX_LOAD_N)``; slip nodes uniform in ``[-1, 1]``. ``z_lat`` is
    :func:`lateral_sinkage` at the slip magnitude ``|slip| LAT_SLIP_MAX``.
    """
    loads = (np.linspace(0.0, 1.0, N_LOAD) ** 2) * MAX_LOAD_N
    loads[0] = 1e-3 * MAX_LOAD_N / (N_LOAD - 1) ** 2  # avoid 0/0 at the first node
    zs = sinkage_grid(soil)
    slips = np.linspace(-1.0, 1.0, N_SLIP)
    z_lat = {k: lateral_sinkage(soil, wheel, loads, abs(float(slips[k])) * LAT_SLIP_MAX)
             for k in range(N_SLIP) if slips[k] >= 0.0}  # fmt: skip
    rows: list[tuple[float, ...]] = []
    for k, slip in enumerate(slips):
        q = integrate(soil, wheel, zs, float(slip))
        z_at = first_sinkage_carrying(loads, q["W"], zs)
        qq = integrate(soil, wheel, z_at, float(slip))
        zl = z_lat[k if slip >= 0.0 else N_SLIP - 1 - k]
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
                    float(zl[k_]),
                )
            )
    return rows, MAX_LOAD_N
