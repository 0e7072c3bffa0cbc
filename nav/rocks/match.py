"""Step 5 of rock-based localisation (Li et al., REFERENCE.md section 5): matching rocks between two sites -
candidate pairs by model parameters, the geometric pattern of their positions (RANSAC for a 4-DOF transform),
a weighted least-squares transform and a significance test against chance agreement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from nav.rocks.params import ExtractedRock

# ================================================================================================================
# Step 5: matching rocks between two sites
# ================================================================================================================


@dataclass(frozen=True)
class Pose4:
    """A rigid transform with yaw only (x, y, z, yaw): ``p -> Rz(yaw) p + t``.

    Roll and pitch of every site frame come from the accelerometers (gravity), so the frames of two sites differ
    by a heading and a translation only.
    """

    t_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    yaw_rad: float = 0.0

    @property
    def R(self) -> np.ndarray:
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def apply(self, points: np.ndarray) -> np.ndarray:
        return np.asarray(points, dtype=float) @ self.R.T + self.t_m

    def compose(self, other: Pose4) -> Pose4:
        """``self o other``: apply ``other`` first."""
        return Pose4(self.R @ other.t_m + self.t_m, wrap(self.yaw_rad + other.yaw_rad))

    def inverse(self) -> Pose4:
        return Pose4(-(self.R.T @ self.t_m), -self.yaw_rad)

    def as_vector(self) -> np.ndarray:
        return np.r_[self.t_m, self.yaw_rad]

    @staticmethod
    def from_vector(v: np.ndarray) -> Pose4:
        return Pose4(np.asarray(v[:3], dtype=float).copy(), float(v[3]))


@dataclass(frozen=True)
class MatchParams:
    """Tuning of :func:`match_rocks`."""

    max_descriptor_diff: float = 0.45  # mean |log ratio| of height, diameter, volume^1/3, area^1/2
    prior_radius_m: float = 1.0  # a pair is a candidate if it agrees with the prior transform within this ...
    prior_radius_frac: float = 0.10  # ... plus this fraction of the distance between the sites
    max_yaw_rad: float = math.radians(10.0)  # largest heading correction a hypothesis may make
    inlier_base_m: float = 0.25  # a pair agrees with a transform within this plus three position sigmas
    min_matches: int = 4
    significance: float = 3.0  # matches must be this many times the chance level (shifted transforms) ...
    null_shift_m: float = 3.0  # ... shifted by this much
    ransac_hypotheses: int = 4000
    seed: int = 0
    # tie-point position sigmas (apex of a fitted model): a floor, the stereo range noise k r^2 along the line of
    # sight and an angular term across it
    sigma_floor_m: float = 0.05
    range_sigma_per_m2: float = 2.4e-4
    angular_sigma_rad: float = 1.0e-3


@dataclass(frozen=True)
class SiteRocks:
    """The rocks of one site in its estimated frame, with the cameras' position there (for range weighting)."""

    rocks: list[ExtractedRock]
    sensor_xyz_m: np.ndarray

    @property
    def positions(self) -> np.ndarray:
        return np.array([r.position_m for r in self.rocks]).reshape(-1, 3)

    @property
    def descriptors(self) -> np.ndarray:
        return np.array([r.model.descriptor() for r in self.rocks]).reshape(-1, 4)

    def covariances(self, params: MatchParams = MatchParams()) -> np.ndarray:
        """(N, 3, 3) position covariances of the tie points: long along the line of sight (stereo range noise)."""
        return tie_point_covariances(self.positions, self.sensor_xyz_m, params)


def tie_point_covariances(positions: np.ndarray, sensor_xyz: np.ndarray, params: MatchParams) -> np.ndarray:
    """(N, 3, 3): ``sigma_floor + k r^2`` along the line of sight, ``sigma_floor + r * angular`` across it."""
    p = np.asarray(positions, dtype=float).reshape(-1, 3)
    ray = p - np.asarray(sensor_xyz, dtype=float)
    r = np.linalg.norm(ray, axis=1)
    u = ray / np.maximum(r, 1e-9)[:, None]
    s_along = params.sigma_floor_m + params.range_sigma_per_m2 * r * r
    s_across = params.sigma_floor_m + params.angular_sigma_rad * r
    eye = np.eye(3)[None]
    uu = u[:, :, None] * u[:, None, :]
    return (s_along**2)[:, None, None] * uu + (s_across**2)[:, None, None] * (eye - uu)


@dataclass(frozen=True)
class SiteMatch:
    """Result of :func:`match_rocks`: index pairs ``(i in a, j in b)`` and ``transform`` mapping b's frame to a's."""

    pairs: np.ndarray  # (M, 2) int
    transform: Pose4
    covariance: np.ndarray  # (4, 4) of (tx, ty, tz, yaw)
    rms_m: float
    n_candidates: int

    @property
    def ok(self) -> bool:
        return len(self.pairs) > 0


def wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def descriptor_difference(da: np.ndarray, db: np.ndarray) -> np.ndarray:
    """(Na, Nb) mean absolute log ratio of the model descriptors (0: identical sizes)."""
    la = np.log(np.maximum(da, 1e-6))[:, None, :]
    lb = np.log(np.maximum(db, 1e-6))[None, :, :]
    return np.abs(la - lb).mean(axis=2)


def fit_pose4(a: np.ndarray, b: np.ndarray, cov: np.ndarray | None = None, x0: Pose4 | None = None) -> Pose4:
    """Transform ``T`` minimising ``sum (a - T b)^T W (a - T b)`` (``W`` the inverse of ``cov``, or identity).

    Closed form (2-D Procrustes in yaw, mean offset in z) without covariances; Gauss-Newton from it (or ``x0``)
    with them.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x0 is None:
        ca, cb = a.mean(axis=0), b.mean(axis=0)
        qa, qb = a[:, :2] - ca[:2], b[:, :2] - cb[:2]
        yaw = math.atan2(float(np.sum(qb[:, 0] * qa[:, 1] - qb[:, 1] * qa[:, 0])), float(np.sum(qb * qa)))
        T = Pose4(np.zeros(3), yaw)
        T = Pose4(ca - T.R @ cb, yaw)
    else:
        T = x0
    if cov is None:
        return T
    W = np.linalg.inv(cov)
    x = T.as_vector()
    for _ in range(10):
        Tx = Pose4.from_vector(x)
        r = a - Tx.apply(b)  # (N, 3)
        dR = np.array([[-math.sin(x[3]), -math.cos(x[3]), 0.0], [math.cos(x[3]), -math.sin(x[3]), 0.0], [0, 0, 0]])
        J = np.zeros((len(a), 3, 4))  # d(T b)/dx
        J[:, :, :3] = np.eye(3)
        J[:, :, 3] = b @ dR.T
        H = np.einsum("nki,nkl,nlj->ij", J, W, J)
        g = np.einsum("nki,nkl,nl->i", J, W, r)
        step = np.linalg.solve(H + 1e-9 * np.eye(4), g)
        x = x + step
        if np.abs(step).max() < 1e-7:
            break
    return Pose4.from_vector(x)


def match_rocks(
    a: SiteRocks, b: SiteRocks, prior: Pose4 | None = None, params: MatchParams = MatchParams()
) -> SiteMatch:
    """Step 5: match the rocks of two sites; ``prior`` maps b's frame to a's (identity: the onboard estimates).

    1. Candidate pairs by model parameters: descriptors (height, equivalent diameter, volume, surface area) within
       ``max_descriptor_diff``, positions within the prior's uncertainty (``prior_radius_m`` plus
       ``prior_radius_frac`` of the sites' separation).
    2. Geometric pattern: hypotheses from two candidate pairs whose inter-rock distances agree (a 4-DOF transform,
       yaw within ``max_yaw_rad`` of the prior) are scored by the candidate pairs they bring into agreement
       (within ``inlier_base_m`` plus three position sigmas), weighted by descriptor similarity; the best wins.
    3. One-to-one assignment of the agreeing pairs, a weighted least-squares transform from them (covariances
       long along each line of sight), re-gated and refitted twice.
    4. Significance: the matches must number ``significance`` times those the same transform shifted by
       ``null_shift_m`` gathers by chance; otherwise no match is returned.
    """
    prior = prior or Pose4()
    pa, pb = a.positions, b.positions
    empty = SiteMatch(np.zeros((0, 2), dtype=int), prior, np.eye(4), math.nan, 0)
    if len(pa) < 2 or len(pb) < 2:
        return empty
    ca, cb = a.covariances(params), b.covariances(params)
    sep = float(np.linalg.norm(a.sensor_xyz_m[:2] - prior.apply(b.sensor_xyz_m[None])[0, :2]))
    # 1. candidates by model parameters and the prior
    desc = descriptor_difference(a.descriptors, b.descriptors)
    pb_prior = prior.apply(pb)
    dist_prior = np.linalg.norm(pa[:, None, :2] - pb_prior[None, :, :2], axis=2)
    radius = params.prior_radius_m + params.prior_radius_frac * sep
    ii, jj = np.nonzero((desc <= params.max_descriptor_diff) & (dist_prior <= radius))
    n_cand = len(ii)
    if n_cand < 2:
        return replace(empty, n_candidates=n_cand)
    weight = 1.0 - desc[ii, jj] / params.max_descriptor_diff
    sig = np.sqrt(np.trace(ca, axis1=1, axis2=2)[ii] + np.trace(cb, axis1=1, axis2=2)[jj])  # per pair
    tol = params.inlier_base_m + 3.0 * sig
    # 2. geometric pattern: RANSAC over two candidate pairs
    rng = np.random.default_rng(params.seed)
    n_hyp = min(params.ransac_hypotheses, n_cand * (n_cand - 1) // 2)
    if n_cand * (n_cand - 1) // 2 <= params.ransac_hypotheses:
        s1, s2 = np.triu_indices(n_cand, 1)
    else:
        s1 = rng.integers(0, n_cand, n_hyp)
        s2 = rng.integers(0, n_cand, n_hyp)
    ok = (ii[s1] != ii[s2]) & (jj[s1] != jj[s2])
    la = np.linalg.norm(pa[ii[s1], :2] - pa[ii[s2], :2], axis=1)
    lb = np.linalg.norm(pb[jj[s1], :2] - pb[jj[s2], :2], axis=1)
    ok &= (np.abs(la - lb) <= tol[s1] + tol[s2]) & (la > 1.0)
    best_score, best_T = -1.0, prior
    for h in np.flatnonzero(ok):
        T = fit_pose4(np.stack([pa[ii[s1[h]]], pa[ii[s2[h]]]]), np.stack([pb[jj[s1[h]]], pb[jj[s2[h]]]]))
        if abs(wrap(T.yaw_rad - prior.yaw_rad)) > params.max_yaw_rad:
            continue
        err = np.linalg.norm(pa[ii] - T.apply(pb[jj]), axis=1)
        score = float(np.sum(weight * (err <= tol)))
        if score > best_score:
            best_score, best_T = score, T
    if best_score < 0:
        return replace(empty, n_candidates=n_cand)
    # 3. assignment, weighted least squares, re-gating
    T = best_T
    pairs = np.zeros((0, 2), dtype=int)
    for _ in range(3):
        pairs = _assign(pa, pb, T, desc, ca, cb, params)
        if len(pairs) < 2:
            break
        cov = ca[pairs[:, 0]] + np.einsum("ij,njk,lk->nil", T.R, cb[pairs[:, 1]], T.R)
        T = fit_pose4(pa[pairs[:, 0]], pb[pairs[:, 1]], cov, x0=T)
    if len(pairs) < max(params.min_matches, params.significance * _chance_matches(pa, pb, T, desc, ca, cb, params)):
        return SiteMatch(np.zeros((0, 2), dtype=int), prior, np.eye(4), math.nan, n_cand)
    cov = ca[pairs[:, 0]] + np.einsum("ij,njk,lk->nil", T.R, cb[pairs[:, 1]], T.R)
    res = pa[pairs[:, 0]] - T.apply(pb[pairs[:, 1]])
    return SiteMatch(pairs, T, pose4_covariance(pb[pairs[:, 1]], T, cov), float(np.sqrt(np.mean(res**2))), n_cand)


def _assign(
    pa: np.ndarray, pb: np.ndarray, T: Pose4, desc: np.ndarray, ca: np.ndarray, cb: np.ndarray, params: MatchParams
) -> np.ndarray:
    """One-to-one pairs agreeing with ``T`` (Mahalanobis gate and descriptor gate), by the Hungarian method."""
    from scipy.optimize import linear_sum_assignment

    tb = T.apply(pb)
    diff = pa[:, None, :] - tb[None, :, :]
    sig2 = np.trace(ca, axis1=1, axis2=2)[:, None] + np.trace(cb, axis1=1, axis2=2)[None, :]
    dist = np.linalg.norm(diff, axis=2)
    gate = (dist <= params.inlier_base_m + 3.0 * np.sqrt(sig2)) & (desc <= params.max_descriptor_diff)
    cost = np.where(gate, dist**2 / sig2 + desc / params.max_descriptor_diff, 1e6)
    rows, cols = linear_sum_assignment(cost)
    keep = gate[rows, cols]
    return np.column_stack([rows[keep], cols[keep]]).astype(int)


def _chance_matches(
    pa: np.ndarray, pb: np.ndarray, T: Pose4, desc: np.ndarray, ca: np.ndarray, cb: np.ndarray, params: MatchParams
) -> float:
    """Mean number of pairs that agree with ``T`` shifted by ``null_shift_m`` in eight directions: how many
    matches two unrelated rock fields of these densities give by chance."""
    counts = []
    for k in range(8):
        a = k * math.pi / 4
        shift = Pose4(T.t_m + params.null_shift_m * np.array([math.cos(a), math.sin(a), 0.0]), T.yaw_rad)
        counts.append(len(_assign(pa, pb, shift, desc, ca, cb, params)))
    return float(np.mean(counts))


def pose4_covariance(b: np.ndarray, T: Pose4, cov: np.ndarray) -> np.ndarray:
    """(4, 4) covariance of a weighted least-squares :class:`Pose4` (inverse Gauss-Newton Hessian)."""
    W = np.linalg.inv(cov)
    y = T.yaw_rad
    dR = np.array([[-math.sin(y), -math.cos(y), 0.0], [math.cos(y), -math.sin(y), 0.0], [0.0, 0.0, 0.0]])
    J = np.zeros((len(b), 3, 4))
    J[:, :, :3] = np.eye(3)
    J[:, :, 3] = b @ dR.T
    H = np.einsum("nki,nkl,nlj->ij", J, W, J)
    return np.linalg.inv(H + 1e-12 * np.eye(4))
