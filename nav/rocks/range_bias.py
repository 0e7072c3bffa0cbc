"""Self-calibration of the panorama's stereo range bias from rocks seen at two sites (ground processing).

A stereo pair's toe-in error (the relative yaw of its calibration, ``theta``) adds a constant to every disparity, so
it adds a constant to inverse range: ``1 / Z_measured = 1 / Z + beta`` with ``beta = theta / B`` (1/m; ``B`` the
baseline). Ranges come out ``Z' = Z / (1 + beta Z)``: about ``beta Z^2`` off, 0.9 m at 25 m for ``theta`` = 0.27 mrad
and the navcams' 20 cm. No single pair shows it (rows are untouched, :mod:`nav.epipolar` cannot see it), but two
sites do: a rock seen 20 m away from one site and 6 m away from the next is displaced along the line of sight by
very different amounts, and no rigid transform between the sites takes that out. :func:`estimate_inverse_range_bias`
finds the ``beta`` under which the matched rocks of every site pair fit a rigid transform best (a 1-D robust search;
tie-point covariances as in :func:`nav.rocks.match.tie_point_covariances`), and :func:`correct_rocks` moves each
point, plane and model along its line of sight from the site's cameras. This is the self-calibrating bundle
adjustment of photogrammetry (Brown 1971; Fraser 1997) cut to the one parameter the rover's own data cannot fix:
MER's rock-based localisation ran on the ground (Li et al., REFERENCE section 5), where such a step belongs.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from nav.rocks.match import MatchParams, SiteMatch, SiteRocks, fit_pose4, tie_point_covariances
from nav.rocks.params import ExtractedRock

MAX_BETA_PER_M = 0.01  # |beta| searched: toe-in up to 2 mrad on a 20 cm baseline (ten times the calibration's sigma)
MAX_RANGE_FACTOR = 0.5  # beta Z stays above -0.5 and below 0.5 for every point corrected (else the point is kept)
TRUNCATE_CHI2 = 16.0  # a tie point's whitened squared residual counts at most this much (4 sigma): wrong matches
MIN_TIE_POINTS = 6  # site pairs with fewer matched rocks do not take part


@dataclass(frozen=True)
class RangeBiasFit:
    """The fitted inverse-range bias (1/m) and what it was fitted on: the robust cost at the fit and at zero."""

    beta_per_m: float
    n_pairs: int
    n_tie_points: int
    cost_at_fit: float
    cost_at_zero: float

    def toe_in_rad(self, baseline_m: float) -> float:
        """The disparity offset as the pair's relative yaw (rad) for a baseline of ``baseline_m``."""
        return self.beta_per_m * baseline_m

    def range_error_m(self, range_m: float) -> float:
        """How much farther than true a point at ``range_m`` (true) came out before the correction."""
        return range_m / (1.0 + self.beta_per_m * range_m) - range_m


def corrected_points(points: np.ndarray, sensor_xyz: np.ndarray, beta_per_m: float) -> np.ndarray:
    """Points (N, 3) moved along their lines of sight from ``sensor_xyz``: ``Z = Z' / (1 - beta Z')`` with the
    range standing in for depth (the panorama frames are within 25 deg of their axes: at most 6 % of the
    correction). Points where ``|beta Z'|`` would exceed ``MAX_RANGE_FACTOR`` are left where they are."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    s = np.asarray(sensor_xyz, dtype=float)
    ray = p - s
    z = np.linalg.norm(ray, axis=1)
    bz = beta_per_m * z
    k = np.where(np.abs(bz) < MAX_RANGE_FACTOR, 1.0 / (1.0 - np.clip(bz, -MAX_RANGE_FACTOR, MAX_RANGE_FACTOR)), 1.0)
    return s + k[:, None] * ray


def correct_rock(rock: ExtractedRock, sensor_xyz: np.ndarray, beta_per_m: float) -> ExtractedRock:
    """``rock`` with its peak, points, tie point and every model moved along the line of sight; its local plane
    and the models' sizes scaled by the correction at the rock (a similarity about the cameras there)."""
    s = np.asarray(sensor_xyz, dtype=float)
    at = corrected_points(rock.position_m[None], s, beta_per_m)[0]
    k = float(np.linalg.norm(at - s) / max(np.linalg.norm(rock.position_m - s), 1e-9))

    def moved(p: np.ndarray) -> np.ndarray:
        return corrected_points(np.asarray(p)[None], s, beta_per_m)[0]

    def model(m):  # noqa: ANN001, ANN202 - RockModel
        return replace(m, centre_xyz_m=moved(m.centre_xyz_m), length_m=m.length_m * k, width_m=m.width_m * k,
                       height_m=m.height_m * k)  # fmt: skip

    plane = rock.plane
    plane = replace(plane, offset_m=k * plane.offset_m + (1.0 - k) * float(plane.normal @ s))
    return replace(
        rock,
        peak=replace(rock.peak, xyz_m=moved(rock.peak.xyz_m), height_range_m=rock.peak.height_range_m * k),
        plane=plane,
        height_m=rock.height_m * k,
        points=corrected_points(rock.points, s, beta_per_m),
        model=model(rock.model),
        models={name: model(m) for name, m in rock.models.items()},
        tie_xyz_m=None if rock.tie_xyz_m is None else moved(rock.tie_xyz_m),
    )


def correct_rocks(site: SiteRocks, beta_per_m: float) -> SiteRocks:
    """Every rock of ``site`` corrected (:func:`correct_rock`)."""
    return SiteRocks([correct_rock(r, site.sensor_xyz_m, beta_per_m) for r in site.rocks], site.sensor_xyz_m)


def _pair_cost(a: SiteRocks, b: SiteRocks, pairs: np.ndarray, beta: float, params: MatchParams) -> float:
    """Truncated chi-square of the best 4-dof transform between the matched rocks of two sites, both corrected
    with ``beta``."""
    pa = corrected_points(a.positions[pairs[:, 0]], a.sensor_xyz_m, beta)
    pb = corrected_points(b.positions[pairs[:, 1]], b.sensor_xyz_m, beta)
    ca = tie_point_covariances(pa, a.sensor_xyz_m, params)
    cb = tie_point_covariances(pb, b.sensor_xyz_m, params)
    T0 = fit_pose4(pa, pb)
    cov = ca + np.einsum("ij,njk,lk->nil", T0.R, cb, T0.R)
    T = fit_pose4(pa, pb, cov, x0=T0)
    r = pa - T.apply(pb)
    chi2 = np.einsum("ni,nij,nj->n", r, np.linalg.inv(cov), r)
    return float(np.minimum(chi2, TRUNCATE_CHI2).sum())


def estimate_inverse_range_bias(
    sites: list[SiteRocks],
    matches: dict[tuple[int, int], SiteMatch],
    params: MatchParams = MatchParams(),
    step_per_m: float = 2.5e-4,
) -> RangeBiasFit | None:
    """The inverse-range bias ``beta`` (1/m) minimising the summed robust cost of every matched site pair (grid
    over +-``MAX_BETA_PER_M``, then a parabola through the best three); None without a usable pair."""
    usable = [(i, j, m.pairs) for (i, j), m in sorted(matches.items()) if m.ok and len(m.pairs) >= MIN_TIE_POINTS]
    if not usable:
        return None

    def cost(beta: float) -> float:
        return sum(_pair_cost(sites[i], sites[j], pairs, beta, params) for i, j, pairs in usable)

    grid = np.arange(-MAX_BETA_PER_M, MAX_BETA_PER_M + 0.5 * step_per_m, step_per_m)
    costs = np.array([cost(float(b)) for b in grid])
    k = int(np.argmin(costs))
    beta = float(grid[k])
    if 0 < k < len(grid) - 1:
        c0, c1, c2 = costs[k - 1], costs[k], costs[k + 1]
        curvature = c0 - 2.0 * c1 + c2
        if curvature > 0:
            beta += 0.5 * step_per_m * (c0 - c2) / curvature
    n_ties = sum(len(p) for _, _, p in usable)
    return RangeBiasFit(beta, len(usable), n_ties, cost(beta), cost(0.0))

