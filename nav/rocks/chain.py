"""Step 6 of rock-based localisation (Li et al., REFERENCE.md section 5): incremental adjustment of a chain of
sites, a weighted least-squares pose graph over the site poses with the matched rocks as tie points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.optimize import least_squares

from nav.rocks.match import (
    MatchParams,
    Pose4,
    SiteMatch,
    SiteRocks,
    fit_pose4,
    match_rocks,
    pose4_covariance,
    tie_point_covariances,
    wrap,
)

# ================================================================================================================
# Step 6: incremental adjustment of a chain of sites
# ================================================================================================================


@dataclass(frozen=True)
class ChainParams:
    """Tuning of :class:`SiteChain`: the error models of the two kinds of observation.

    Odometry legs: the position covariance VO reports for its own steps (summed over the leg by the caller) when
    given, else ``odometry_sigma_floor_m + odometry_sigma_frac * distance`` per axis; the heading is the gyro's
    (MER keeps the IMU attitude, VO corrects only position), so the leg's heading drift has the gyro datasheet's
    bias instability times the leg's duration and its angle random walk times the root of it (LN-200 class:
    1 deg/h, 0.07 deg/sqrt(h); without a duration, ``odometry_yaw_sigma_rad_per_m`` per metre). A heading (and
    pitch) error growing over the leg moves its end across the track (and in height) by half the leg times it.
    """

    odometry_sigma_frac: float = 0.02  # fallback without VO's covariance (VO: ~1-2 %; wheel odometry ~5-10 %)
    odometry_sigma_floor_m: float = 0.05
    odometry_yaw_sigma_rad_per_m: float = math.radians(0.1)  # fallback without the leg's duration
    gyro_bias_instability_deg_h: float = 1.0  # datasheet figures of the IMU (LN-200 class, REFERENCE section 1)
    gyro_arw_deg_sqrt_h: float = 0.07
    max_match_distance_m: float = 26.0  # sites farther apart than this are not matched (paper: reliable to 26 m)
    # self-calibrated systematic errors of the tie points (rock apexes): 0 none, 1 an offset along the line of
    # sight (SAD windows on a convex rock see it a little too far), 2 also a height error growing with the range
    range_bias_terms: int = 2
    range_bias_prior_m: float = 0.1  # prior sigma of each term
    # robust tie points (Baarda-style data snooping): a matched pair whose residual, normalised by its covariance
    # and by the robust scale of the pair's residuals, exceeds this chi-square (3 dof, 99 %) is not a tie point
    # off by default: on the tuning survey (rock_localization --seed 1, half the rocks irregular) it dropped mostly
    # wrong matches but left the adjusted sites no better (docs/navigation/index.md, rock localisation)
    tie_gate_chi2: float = 0.0  # e.g. 11.34 (chi-square, 3 dof, 99 %); 0 disables the gate
    min_tie_points: int = 4  # a rock edge needs this many tie points left after the gate
    # a heading error common to all tie points of one site's panorama (correlated, so not averaged down by the
    # number of rocks and not seen in the match residuals): each rock edge's yaw variance gets twice its square.
    # Measured rock-edge yaw errors reach 0.15 deg at a fitted 0.04-0.07 deg; 0.05 deg chosen on the tuning
    # survey (rock_localization --seed 1, half the rocks irregular) from 0 / 0.05 / 0.1
    rock_yaw_sigma_site_deg: float = 0.05
    # gross rock edges (data snooping on the solved graph, Baarda 1968): a rock edge whose whitened residual after the
    # adjustment exceeds this chi-square (4 dof: x, y, z, heading; 99.9 %, the textbook level, not fitted) is
    # dropped, the worst first, and the chain re-solved. A correlated tie-point error (all matched rocks of a pair
    # seen from far, a bias the match residuals cannot show) can put a whole transform 5 sigma off; the odometry
    # legs and the other rock edges then disagree with it. Odometry legs are never dropped. 0 disables it
    edge_gate_chi2: float = 18.47
    match: MatchParams = MatchParams()


@dataclass
class ChainSite:
    """One site of a chain: its rocks (estimated frame), onboard pose, leg error model and the adjusted pose."""

    rocks: SiteRocks
    estimate: Pose4  # onboard pose (position, heading) in the site's estimated frame
    driven_m: float  # odometry distance from the previous site
    leg_s: float = 0.0  # time since the previous site
    odometry_cov_m2: np.ndarray | None = None  # (3, 3) world covariance of the leg reported by VO
    correction: Pose4 = field(default_factory=Pose4)  # estimated frame -> adjusted world frame
    at_addition: np.ndarray | None = None  # adjusted position right after this site was added (incremental)

    @property
    def estimate_xyz_m(self) -> np.ndarray:
        return self.estimate.t_m

    @property
    def adjusted(self) -> Pose4:
        return self.correction.compose(self.estimate)

    @property
    def adjusted_xyz_m(self) -> np.ndarray:
        return self.adjusted.t_m


@dataclass(frozen=True)
class _Edge:
    """A measured relative pose ``Z = X_i^-1 o X_j`` of two sites (4-vector), its covariance and, for rock edges,
    its sensitivity to the tie-point calibration terms."""

    i: int
    j: int
    z: np.ndarray  # (4,)
    cov: np.ndarray  # (4, 4)
    kind: Literal["odometry", "rocks"]
    d_z_d_bias: np.ndarray | None = None  # (4, n_bias)


class SiteChain:
    """Incremental adjustment of rover sites tied by matched rocks (the paper's step "matched rocks become tie
    points for incremental bundle adjustment of the rover positions"), as a weighted least-squares pose graph.

    Unknowns: the pose :class:`Pose4` (x, y, z, heading) of every site after the first (the datum, fixed at its
    operator-given pose) and the tie points' systematic error terms. Observations, each whitened by its own
    covariance:

    * odometry legs between consecutive sites: the onboard relative pose, with the covariance of
      :class:`ChainParams` (VO's own step covariances, the gyro's heading drift);
    * rock legs between every two sites within ``max_match_distance_m`` whose rocks match (:func:`match_rocks`): the
      site-to-site transform from the matched rocks, with the covariance of its weighted least-squares fit scaled by
      the variance factor of the match residuals (chi-square per degree of freedom). The transform depends on the
      tie points' systematic errors (``range_bias_terms``): its derivative with respect to each is taken by
      refitting the transform with the tie points shifted, so the terms are estimated with the poses. A common
      offset along the lines of sight lengthens every leg the same way, a scale the odometry pins down.

    Site frames are levelled (roll and pitch from the accelerometers at rest), so heading and translation are all
    that differ between them. :meth:`add_site` matches the new site with every earlier site within
    ``max_match_distance_m`` (estimated), merges the matches into tie points (union-find, for :meth:`tracks`) and
    re-solves the whole chain.
    """

    def __init__(self, params: ChainParams = ChainParams()) -> None:
        self.params = params
        self.sites: list[ChainSite] = []
        self.matches: dict[tuple[int, int], SiteMatch] = {}
        self.range_bias_m: tuple[float, ...] = ()  # estimated tie-point error terms (see ChainParams)
        self.dropped_edges: list[tuple[int, int, float]] = []  # rock edges failing the gate: (i, j, chi-square)
        self._edges: list[_Edge] = []
        self._parent: dict[tuple[int, int], tuple[int, int]] = {}

    # -- building
    def add_site(
        self,
        rocks: SiteRocks,
        estimate_xyz_m: np.ndarray,
        driven_m: float = 0.0,
        estimate_yaw_rad: float = 0.0,
        leg_s: float = 0.0,
        odometry_cov_m2: np.ndarray | None = None,
    ) -> ChainSite:
        """Add the next site: its rocks, onboard pose and the leg from the previous site; match; re-solve."""
        k = len(self.sites)
        estimate = Pose4(np.asarray(estimate_xyz_m, dtype=float).copy(), float(estimate_yaw_rad))
        cov = None if odometry_cov_m2 is None else np.asarray(odometry_cov_m2, dtype=float)
        site = ChainSite(rocks, estimate, float(driven_m), float(leg_s), cov)
        if k > 0:
            site.correction = self.sites[-1].correction  # odometry: no new drift until tie points say otherwise
            self._edges.append(self._odometry_edge(self.sites[-1], site, k))
        self.sites.append(site)
        for j in range(k):
            prev = self.sites[j]
            sep = float(np.linalg.norm(prev.estimate_xyz_m[:2] - site.estimate_xyz_m[:2]))
            if sep > self.params.max_match_distance_m:
                continue
            # prior b -> a: both frames are onboard estimates, so identity up to the corrections already known
            prior = prev.correction.inverse().compose(site.correction)
            m = match_rocks(prev.rocks, rocks, prior, self.params.match)
            if m.ok:
                self.matches[(j, k)] = m
                edge = self._rock_edge(j, k, m)
                if edge is not None:
                    self._edges.append(edge)
                for ia, ib in m.pairs:
                    self._union((j, int(ia)), (k, int(ib)))
        self.solve()
        site.at_addition = site.adjusted_xyz_m.copy()
        return site

    def _odometry_edge(self, a: ChainSite, b: ChainSite, k: int) -> _Edge:
        """The onboard relative pose of consecutive sites and its covariance (see :class:`ChainParams`)."""
        P = self.params
        z = a.estimate.inverse().compose(b.estimate)
        leg = z.t_m
        if b.leg_s > 0:
            hours = b.leg_s / 3600.0
            sig_yaw = math.radians(
                math.hypot(P.gyro_bias_instability_deg_h * hours, P.gyro_arw_deg_sqrt_h * math.sqrt(hours))
            )
        else:
            sig_yaw = P.odometry_yaw_sigma_rad_per_m * max(b.driven_m, 1.0)
        if b.odometry_cov_m2 is not None:
            R = a.estimate.R  # world -> a's frame: the leg is measured in a's frame
            c_t = R.T @ b.odometry_cov_m2 @ R
        else:
            c_t = (P.odometry_sigma_floor_m + P.odometry_sigma_frac * b.driven_m) ** 2 * np.eye(3)
        length = float(np.hypot(leg[0], leg[1]))
        u = leg / max(length, 1e-9) * np.array([1.0, 1.0, 0.0])
        across = np.array([-u[1], u[0], 0.0])
        lever = 0.5 * length  # a drift growing over the leg moves its end by half the leg times the final error
        cov = np.zeros((4, 4))
        cov[:3, :3] = c_t + (lever * sig_yaw) ** 2 * (np.outer(across, across) + np.diag([0.0, 0.0, 1.0]))
        cov[3, 3] = sig_yaw**2
        cov[:3, 3] = cov[3, :3] = lever * sig_yaw**2 * across
        return _Edge(k - 1, k, z.as_vector(), cov, "odometry")

    def _rock_edge(self, i: int, j: int, m: SiteMatch) -> _Edge | None:
        """The relative pose the rock match gives, its covariance (scaled by the match residuals' variance factor)
        and its derivative with respect to the tie-point error terms (by refitting with shifted tie points).

        The pairs are first screened by :func:`robust_tie_points` (a gross tie point, e.g. an irregular rock whose
        model apex moves with the viewpoint, would otherwise bias the transform it is weighted into); ``None`` if
        fewer than ``min_tie_points`` pass."""
        P = self.params
        a, b = self.sites[i], self.sites[j]
        pa = a.rocks.positions[m.pairs[:, 0]]
        pb = b.rocks.positions[m.pairs[:, 1]]
        ca = tie_point_covariances(pa, a.rocks.sensor_xyz_m, P.match)
        cb = tie_point_covariances(pb, b.rocks.sensor_xyz_m, P.match)
        T, keep = robust_tie_points(pa, pb, ca, cb, m.transform, P.tie_gate_chi2)
        if int(keep.sum()) < P.min_tie_points:
            return None
        pa, pb, ca, cb = pa[keep], pb[keep], ca[keep], cb[keep]
        cov_pairs = ca + np.einsum("ij,njk,lk->nil", T.R, cb, T.R)
        res = pa - T.apply(pb)
        chi2 = float(np.einsum("ni,nij,nj->", res, np.linalg.inv(cov_pairs), res))
        variance_factor = chi2 / max(3 * len(res) - 4, 1)

        def relative(t: np.ndarray) -> np.ndarray:
            z = a.estimate.inverse().compose(Pose4.from_vector(t)).compose(b.estimate).as_vector()
            z[3] = wrap(z[3])
            return z

        t0 = T.as_vector()
        z = relative(t0)
        J = _numeric_jacobian(relative, t0, 1e-6)
        cov = J @ (pose4_covariance(pb, T, cov_pairs) * variance_factor) @ J.T
        cov[3, 3] += 2.0 * math.radians(P.rock_yaw_sigma_site_deg) ** 2  # per-site heading error, both sites
        n_bias = P.range_bias_terms
        G = np.zeros((4, n_bias))
        for k in range(n_bias):
            step = 0.01
            theta = np.zeros(n_bias)
            theta[k] = step
            shifted = fit_pose4(
                _remove_tie_bias(pa, a.rocks.sensor_xyz_m, theta),
                _remove_tie_bias(pb, b.rocks.sensor_xyz_m, theta),
                cov_pairs,
                x0=T,
            )
            G[:, k] = (relative(shifted.as_vector()) - z) / step
        return _Edge(i, j, z, cov, "rocks", G)

    def _find(self, x: tuple[int, int]) -> tuple[int, int]:
        self._parent.setdefault(x, x)
        while self._parent[x] != x:
            self._parent[x] = self._parent[self._parent[x]]
            x = self._parent[x]
        return x

    def _union(self, a: tuple[int, int], b: tuple[int, int]) -> None:
        ra, rb = self._find(a), self._find(b)
        if ra != rb:
            self._parent[max(ra, rb)] = min(ra, rb)

    def tracks(self) -> list[list[tuple[int, int]]]:
        """Tie points: groups of (site, rock) observations of one rock, each in at least two sites."""
        groups: dict[tuple[int, int], list[tuple[int, int]]] = {}
        for node in list(self._parent):
            groups.setdefault(self._find(node), []).append(node)
        out = []
        for g in groups.values():
            sites = [s for s, _ in g]
            if len(set(sites)) >= 2 and len(set(sites)) == len(sites):  # one rock per site (else ambiguous)
                out.append(sorted(g))
        return out

    # -- solving
    def solve(self) -> None:
        """Adjust (:meth:`_adjust`), then drop the worst rock edge beyond ``edge_gate_chi2`` and re-adjust, until
        every rock edge passes (see :class:`ChainParams`)."""
        while True:
            chi2 = self._adjust()
            rocks = [k for k, e in enumerate(self._edges) if e.kind == "rocks"]
            if self.params.edge_gate_chi2 <= 0 or not rocks:
                return
            worst = max(rocks, key=lambda k: chi2[k])
            if chi2[worst] <= self.params.edge_gate_chi2:
                return
            e = self._edges.pop(worst)
            self.dropped_edges.append((e.i, e.j, chi2[worst]))

    def _adjust(self) -> list[float]:
        """Weighted least squares over the site poses (site 0 fixed) and the tie-point error terms; returns each
        edge's whitened squared residual at the solution.

        Each edge's residual is the measured relative pose (a rock edge corrected by its derivative times the error
        terms) minus the one the current poses give, whitened by the edge's covariance; the error terms carry a
        prior of ``range_bias_prior_m``.
        """
        n = len(self.sites)
        if n < 2:
            return [0.0] * len(self._edges)
        P = self.params
        n_bias = P.range_bias_terms if any(e.kind == "rocks" for e in self._edges) else 0
        whiten = [np.linalg.cholesky(np.linalg.inv(e.cov)).T for e in self._edges]
        datum = self.sites[0].adjusted

        def poses(x: np.ndarray) -> list[Pose4]:
            return [datum] + [Pose4.from_vector(x[4 * k : 4 * k + 4]) for k in range(n - 1)]

        def residuals(x: np.ndarray) -> np.ndarray:
            X = poses(x)
            bias = x[4 * (n - 1) :]
            out = []
            for e, W in zip(self._edges, whiten, strict=True):
                z = e.z if e.d_z_d_bias is None or not n_bias else e.z + e.d_z_d_bias[:, :n_bias] @ bias
                r = X[e.i].inverse().compose(X[e.j]).as_vector() - z
                r[3] = wrap(r[3])
                out.append(W @ r)
            out.append(bias / P.range_bias_prior_m)
            return np.concatenate(out)

        x0 = np.concatenate([s.adjusted.as_vector() for s in self.sites[1:]] + [np.zeros(n_bias)])
        res = least_squares(residuals, x0, method="trf", x_scale="jac", max_nfev=200)
        X = poses(res.x)
        for k in range(1, n):
            self.sites[k].correction = X[k].compose(self.sites[k].estimate.inverse())
        self.range_bias_m = tuple(float(b) for b in res.x[4 * (n - 1) :])
        r = residuals(res.x)
        return [float(np.sum(r[4 * k : 4 * k + 4] ** 2)) for k in range(len(self._edges))]


CHI2_3DOF_MEDIAN = 2.366  # median of a chi-square with 3 degrees of freedom


def robust_tie_points(
    pa: np.ndarray, pb: np.ndarray, cov_a: np.ndarray, cov_b: np.ndarray, T0: Pose4, gate_chi2: float
) -> tuple[Pose4, np.ndarray]:
    """Screen matched tie points (a in site a's frame, b in b's, ``T0`` mapping b to a) for gross errors.

    Iterated data snooping: refit the weighted least-squares transform on the kept pairs, normalise every pair's
    residual by its covariance (``cov_a + R cov_b R^T``) and by a robust variance factor (median normalised residual
    over the chi-square median, at least 1: the covariance model may be optimistic for all pairs alike), keep those
    within ``gate_chi2``; until the kept set is stable. Returns the transform and the kept mask (all kept if
    ``gate_chi2`` <= 0).
    """
    keep = np.ones(len(pa), dtype=bool)
    T = T0
    if gate_chi2 <= 0 or len(pa) < 3:
        return T, keep
    for _ in range(10):
        cov = cov_a + np.einsum("ij,njk,lk->nil", T.R, cov_b, T.R)
        T = fit_pose4(pa[keep], pb[keep], cov[keep], x0=T)
        r = pa - T.apply(pb)
        d2 = np.einsum("ni,nij,nj->n", r, np.linalg.inv(cov), r)
        scale = max(1.0, float(np.median(d2)) / CHI2_3DOF_MEDIAN)
        new = d2 <= gate_chi2 * scale
        if (new == keep).all() or new.sum() < 3:
            break
        keep = new
    return T, keep


def _remove_tie_bias(points: np.ndarray, sensor_xyz: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Tie points with their systematic errors taken out: ``theta[0]`` along the line of sight (a rock seen too far
    by that much), ``theta[1]`` in height per 30 m of range (rock tops seen too high)."""
    p = np.array(points, dtype=float)
    ray = p - np.asarray(sensor_xyz, dtype=float)
    if len(theta) > 0:
        p -= theta[0] * ray / np.maximum(np.linalg.norm(ray, axis=1), 1e-9)[:, None]
    if len(theta) > 1:
        p[:, 2] -= theta[1] * np.hypot(ray[:, 0], ray[:, 1]) / 30.0
    return p


def _numeric_jacobian(f, x: np.ndarray, eps: float) -> np.ndarray:  # noqa: ANN001
    f0 = f(x)
    J = np.zeros((len(f0), len(x)))
    for k in range(len(x)):
        d = np.zeros(len(x))
        d[k] = eps
        J[:, k] = (f(x + d) - f(x - d)) / (2.0 * eps)
    return J
