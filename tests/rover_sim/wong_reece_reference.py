"""An independent single-wheel Wong–Reece reference (with Ishigami's lateral terms), written apart from the law.

Plain textbook form (Wong & Reece 1967; Wong 2008 sec. 4.2; Ishigami et al. 2007): a rigid smooth wheel of radius
``r`` and width ``b``; normal stress ``sigma = (k_c/b + k_phi) z(theta)^n`` with ``z(theta) = r (cos theta_e -
cos theta1)`` and the peak at ``theta_m = (a0 + a1 s) theta1``; ``n = n0 + n1 s`` (Ding et al. 2011);
``j = r [(theta1 - theta) - (1 - s)(sin theta1 - sin theta)]``; ``tau = (c + sigma tan phi) F(j)`` with the
two-scale mobilisation ``F(j) = w (1 - exp(-j/K)) + (1 - w)(1 - exp(-j/(m K)))`` (``w`` the soil's
``fast_shear_fraction``, ``m`` its ``slow_shear_ratio``; Janosi-Hanamoto ``1 - exp(-j/K)`` when ``w = 1``).
The sinkage is found by bisection on the vertical balance, the integrals by ``scipy.integrate.quad``.

Lateral (Ishigami 2007, slip angle ``beta``): ``j_y = r (1 - s)(theta1 - theta) tan beta``,
``tau_y = (c + sigma tan phi)(1 - exp(-j_y / K_y))`` (Janosi-Hanamoto sideways, as the law),
``F_y = r b int tau_y + int R_b(h(theta)) (r - h cos theta)`` with the Hegedus bulldozing resistance ``R_b`` on
the side wall at depth ``h(theta) = r (cos theta - cos theta1)``.
"""

from __future__ import annotations

import math

from scipy.integrate import quad


def _sigma(theta, th1, thm, k, n, r):
    if theta >= thm:
        te = theta
    else:
        te = th1 - theta / thm * (th1 - thm) if thm > 0 else th1
    return k * max(r * (math.cos(te) - math.cos(th1)), 0.0) ** n


def _mobilised(j: float, soil) -> float:
    """Fraction of the strength mobilised along the rim at displacement ``j >= 0``: two Janosi-Hanamoto terms."""
    w, K, m = soil.fast_shear_fraction, soil.shear_modulus_m, soil.slow_shear_ratio
    return w * (1.0 - math.exp(-j / K)) + (1.0 - w) * (1.0 - math.exp(-j / (m * K)))


def wheel(soil, r: float, b: float, load_n: float, slip: float) -> dict[str, float]:
    """Steady-state sinkage (m), drawbar pull (N), torque (N m) of a driven rigid wheel at slip 0..1."""
    k = soil.k_c / b + soil.k_phi
    n = soil.n0 + soil.n1 * slip
    tphi = math.tan(math.radians(soil.friction_angle_deg))
    c = soil.cohesion_pa

    def tau(theta, th1, thm):
        j = r * ((th1 - theta) - (1.0 - slip) * (math.sin(th1) - math.sin(theta)))
        s = 1.0 if j >= 0 else -1.0
        return (c + _sigma(theta, th1, thm, k, n, r) * tphi) * _mobilised(abs(j), soil) * s

    def integrals(z):
        th1 = math.acos(max(1.0 - z / r, -1.0))
        thm = (soil.a0 + soil.a1 * slip) * th1
        pts = [thm]
        W = (
            r
            * b
            * quad(
                lambda t: _sigma(t, th1, thm, k, n, r) * math.cos(t) + tau(t, th1, thm) * math.sin(t),
                0.0,
                th1,
                points=pts,
            )[0]
        )
        H = r * b * quad(lambda t: tau(t, th1, thm) * math.cos(t), 0.0, th1, points=pts)[0]
        R = r * b * quad(lambda t: _sigma(t, th1, thm, k, n, r) * math.sin(t), 0.0, th1, points=pts)[0]
        T = r * r * b * quad(lambda t: tau(t, th1, thm), 0.0, th1, points=pts)[0]
        return W, H, R, T

    lo, hi = 1e-7, 0.9 * r
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        if integrals(mid)[0] < load_n:
            lo = mid
        else:
            hi = mid
    z = math.sqrt(lo * hi)
    W, H, R, T = integrals(z)
    return {"z": z, "W": W, "DP": H - R, "T": T}


def lateral_force(soil, r: float, b: float, z: float, slip: float, beta_rad: float) -> float:
    """Ishigami's lateral force (shear + side-wall bulldozing) at sinkage ``z``, slip and slip angle ``beta``."""
    k = soil.k_c / b + soil.k_phi
    n = soil.n0 + soil.n1 * slip
    tphi = math.tan(math.radians(soil.friction_angle_deg))
    c, Ky = soil.cohesion_pa, soil.lateral_shear_modulus_m
    th1 = math.acos(1.0 - z / r)
    thm = (soil.a0 + soil.a1 * slip) * th1
    phi = math.radians(soil.friction_angle_deg)
    xc = math.pi / 4 - phi / 2
    d1 = 1 / math.tan(xc) + math.tan(xc + phi)
    d2 = 1 / math.tan(xc) + tphi / math.tan(xc) ** 2
    gamma = soil.density_kg_m3 * 3.711

    def tau_y(t):
        jy = r * (1.0 - slip) * (th1 - t) * math.tan(beta_rad)
        return (c + _sigma(t, th1, thm, k, n, r) * tphi) * (1.0 - math.exp(-abs(jy) / Ky))

    def bull(t):
        h = r * (math.cos(t) - math.cos(th1))
        return d1 * (c * h + 0.5 * d2 * gamma * h * h) * (r - h * math.cos(t))

    shear = r * b * quad(tau_y, 0.0, th1, points=[thm])[0]
    side = quad(bull, -th1, th1)[0]
    return shear + side
