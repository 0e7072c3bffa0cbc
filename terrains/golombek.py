"""Rock size-frequency law of Golombek & Rapp (1997), "Size-frequency distributions of rocks on Mars and Earth
analog sites: implications for future landed missions", JGR 102(E2).

The cumulative fractional area covered by rocks of diameter ``D`` or larger is ``F_k(D) = k exp(-q(k) D)``
with ``q(k) = 1.79 + 0.152 / k`` (D in metres), ``k`` the total rock cover (Viking Lander 1 about 0.07, Viking
Lander 2 about 0.16, Pathfinder about 0.19; the Meridiani plains nearly 0). Dividing ``-dF/dD`` by a rock's
area ``pi D^2 / 4`` gives the number density per unit diameter, ``n(D) = 4 k q exp(-q D) / (pi D^2)``, whose
integral is the cumulative number per square metre used here to draw rock counts and sizes.
"""

from __future__ import annotations

import numpy as np
from scipy.special import exp1


def golombek_q_per_m(cover_fraction: float) -> float:
    """``q(k) = 1.79 + 0.152 / k`` in 1/m; infinite for ``k = 0`` (no rocks)."""
    return np.inf if cover_fraction <= 0.0 else 1.79 + 0.152 / cover_fraction


def cumulative_area_fraction(diameter_m: np.ndarray | float, cover_fraction: float) -> np.ndarray:
    """``F_k(D)``: fraction of the ground covered by rocks of diameter ``>= D``."""
    d = np.asarray(diameter_m, dtype=np.float64)
    if cover_fraction <= 0.0:
        return np.zeros_like(d)
    return cover_fraction * np.exp(-golombek_q_per_m(cover_fraction) * d)


def cumulative_number_per_m2(diameter_m: np.ndarray | float, cover_fraction: float) -> np.ndarray:
    """Number of rocks of diameter ``>= D`` per square metre: ``(4kq/pi) (exp(-qD)/D - q E1(qD))``."""
    d = np.asarray(diameter_m, dtype=np.float64)
    q = golombek_q_per_m(cover_fraction)
    if not np.isfinite(q):  # k = 0, or so small that q overflows: no rocks
        return np.zeros_like(d)
    with np.errstate(over="ignore", invalid="ignore"):
        n = 4.0 * cover_fraction * q / np.pi * (np.exp(-q * d) / d - q * exp1(q * d))
    return np.maximum(np.nan_to_num(n, nan=0.0, posinf=0.0), 0.0)


def sample_diameters_m(
    cover_fraction: float, min_diameter_m: float, area_m2: float, rng: np.random.Generator
) -> np.ndarray:
    """Rock diameters ``>= min_diameter_m`` on ``area_m2`` of ground, sorted largest first.

    The count is Poisson with mean ``N(>= D_min) * area``; sizes come from inverting the cumulative number
    ``N(>= D)`` on a dense table (relative error well below 1e-3).
    """
    q = golombek_q_per_m(cover_fraction)
    n_total = float(cumulative_number_per_m2(min_diameter_m, cover_fraction)) * area_m2
    if not (np.isfinite(q) and n_total > 0.0):
        return np.zeros(0)
    count = int(rng.poisson(n_total))
    if count == 0:
        return np.zeros(0)
    # Table of the tail fraction G(D) = N(>=D) / N(>=D_min), from 1 at D_min down to ~exp(-60).
    offsets = np.geomspace(1e-5 * min(min_diameter_m, 1.0 / q), 60.0 / q, 4096)
    d_table = np.concatenate([[min_diameter_m], min_diameter_m + offsets])
    tail = cumulative_number_per_m2(d_table, cover_fraction) / (n_total / area_m2)
    u = rng.uniform(0.0, 1.0, count)
    diameters = np.interp(u, tail[::-1], d_table[::-1])
    return np.sort(diameters)[::-1]
