"""Step 4 of rock-based localisation (Li et al., REFERENCE.md section 5): least-squares fits of a hemispheroid, a
semi-ellipsoid, a cone and a tetrahedron to a rock's points, with iterative removal of far points, and the
choice of model (an information criterion).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from nav.rocks.params import ROCK_SHAPES, LocalPlane, RockModel, RockParams, RockShape

# ================================================================================================================
# Step 4: rock models
# ================================================================================================================


def _model_parts(shape: RockShape, x: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """(cx, cy, a, b, h, yaw) from a shape's parameter vector (hemispheroid: b = a, no yaw)."""
    if shape == "hemispheroid":
        cx, cy, a, h = x
        return cx, cy, a, a, h, 0.0
    cx, cy, a, b, h, yaw = x
    return cx, cy, a, b, h, yaw


def model_distance(
    shape: RockShape, x: np.ndarray, local_xyz: np.ndarray, with_normals: bool = False
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Approximate signed orthogonal distance (m, + outside) of plane-frame points to a rock model surface.

    Ellipsoids: ``(rho - 1) / |grad rho|`` with ``rho`` the normalised radius (exact for a sphere, first order in
    the distance otherwise); cone and tetrahedron: the vertical residual times the cosine of the surface slope
    (exact on a facet). Outside the footprint the nearest surface is the ground plane or the rock's flank,
    whichever is closer. ``with_normals``: also the (N, 3) unit surface normals there (plane frame).
    """
    cx, cy, a, b, h, yaw = _model_parts(shape, x)
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy, z = local_xyz[:, 0] - cx, local_xyz[:, 1] - cy, local_xyz[:, 2]
    u = c * dx + s * dy
    v = -s * dx + c * dy
    un, vn = u / a, v / b
    if shape in ("hemispheroid", "semi_ellipsoid"):
        zn = np.maximum(z, 0.0) / h
        rho = np.sqrt(un * un + vn * vn + zn * zn)  # normalised radius: 1 on the surface
        gu, gv, gz = un / a, vn / b, zn / h  # grad rho, times rho
        grad = np.sqrt(gu * gu + gv * gv + gz * gz) / np.maximum(rho, 1e-9)
        surface = (rho - 1.0) / np.maximum(grad, 1e-9)  # first order in the distance; exact for a sphere
        outside = un * un + vn * vn > 1.0
    else:
        if shape == "cone":
            rn = np.maximum(np.hypot(un, vn), 1e-9)
            frac = 1.0 - rn
            gu, gv = h * un / (a * rn), h * vn / (b * rn)  # minus the height gradient
        else:  # tetrahedron: a pyramid over the base triangle, planar faces
            faces = np.stack([-1.5 * un, 0.75 * (un + 2.0 * vn), 0.75 * (un - 2.0 * vn)])
            which = np.argmax(faces, axis=0)
            frac = 1.0 - faces[which, np.arange(len(un))]
            gu = h * np.array([-1.5, 0.75, 0.75])[which] / a
            gv = h * np.array([0.0, 1.5, -1.5])[which] / b
        gz = np.ones_like(gu)
        surface = (z - h * frac) / np.sqrt(1.0 + gu * gu + gv * gv)  # the rotation keeps the gradient's norm
        outside = frac <= 0.0
    ground = (z < 0.0) | (outside & (z < surface))
    dist = np.where(ground, z, surface)
    if not with_normals:
        return dist
    normal = np.stack([c * gu - s * gv, s * gu + c * gv, gz], axis=1)
    normal[ground] = (0.0, 0.0, 1.0)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    return dist, normal


def _initial_guesses(shape: RockShape, local: np.ndarray, height_m: float) -> list[np.ndarray]:
    """Starting parameter vectors: centre at the peak (origin), size from the points' spread, yaw from PCA."""
    xy = local[:, :2]
    eigvals, vecs = np.linalg.eigh(np.cov(xy.T) if len(xy) > 2 else np.eye(2) * 0.01)
    spread = np.sqrt(np.maximum(eigvals, 1e-6))  # minor, major
    yaw0 = math.atan2(vecs[1, 1], vecs[0, 1])  # major axis
    reach = float(np.percentile(np.hypot(xy[:, 0], xy[:, 1]), 90)) if len(xy) else height_m
    a0 = max(reach, 0.5 * height_m, 0.05)
    b0 = max(a0 * spread[0] / max(spread[1], 1e-6), 0.5 * a0)
    h0 = max(height_m, 0.03)
    if shape == "hemispheroid":
        return [np.array([0.0, 0.0, a0, h0])]
    if shape == "semi_ellipsoid":
        return [np.array([0.0, 0.0, a0, b0, h0, yaw0])]
    if shape == "cone":
        return [np.array([0.0, 0.0, 1.2 * a0, 1.2 * b0, h0, yaw0])]
    # tetrahedron: the apex above the centroid; try the triangle's three orientations about the major axis
    return [np.array([0.0, 0.0, 1.2 * a0, 1.2 * b0, h0, yaw0 + k * 2.0 * math.pi / 3.0]) for k in range(3)]


def _bounds(shape: RockShape, height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Parameter bounds around the step-2 height: apex near the peak, height within 40 %, sane axes."""
    h = max(height_m, 0.03)
    c = max(0.6 * h, 0.2)
    ax_lo, ax_hi = 0.25 * h, 4.0 * h + 0.2
    h_lo, h_hi = 0.6 * h, 1.4 * h
    if shape == "hemispheroid":
        return np.array([-c, -c, ax_lo, h_lo]), np.array([c, c, ax_hi, h_hi])
    return np.array([-c, -c, ax_lo, ax_lo, h_lo, -np.inf]), np.array([c, c, ax_hi, ax_hi, h_hi, np.inf])


@dataclass(frozen=True)
class PointNoise:
    """Per-point stereo noise for the fits: unit lines of sight (plane frame) and sigmas along and across them."""

    los: np.ndarray  # (N, 3)
    sigma_along_m: np.ndarray  # (N,)
    sigma_across_m: np.ndarray  # (N,)

    def subset(self, sel: np.ndarray) -> PointNoise:
        return PointNoise(self.los[sel], self.sigma_along_m[sel], self.sigma_across_m[sel])

    def sigma_for(self, normals: np.ndarray) -> np.ndarray:
        """Sigma of each point's distance to a surface with these normals: range noise counts as far as the line
        of sight crosses the surface (a face seen head-on takes all of it, a top seen edge-on none)."""
        cos = np.abs(np.einsum("ij,ij->i", normals, self.los))
        return np.sqrt(self.sigma_across_m**2 + (self.sigma_along_m**2 - self.sigma_across_m**2) * cos * cos)


def fit_rock_model(
    shape: RockShape,
    local_xyz: np.ndarray,
    height_m: float,
    params: RockParams = RockParams(),
    noise: PointNoise | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Least-squares fit of one model to plane-frame points (peak foot at the origin), dropping far points.

    Residuals are surface distances (:func:`model_distance`), divided by each point's noise sigma for that surface
    when ``noise`` is given (stereo smears a distant rock along the lines of sight: its faces seen head-on are
    uncertain, its outline is not). Each round fits the current inliers (``scipy.optimize.least_squares``, trust
    region, from every initial guess in the first round), then keeps the points within ``outlier_sigma`` RMS of
    the surface (and always those within ``outlier_floor_m``). Returns ``(parameters, inlier mask)``.
    """
    pts = np.asarray(local_xyz, dtype=float)
    if len(pts) < 5:
        return None
    lo, hi = _bounds(shape, height_m)
    keep = np.ones(len(pts), dtype=bool)
    guesses = _initial_guesses(shape, pts, height_m)
    best_x = None

    def scaled(x: np.ndarray, sel: np.ndarray) -> np.ndarray:
        if noise is None:
            return model_distance(shape, x, pts[sel])
        d, n = model_distance(shape, x, pts[sel], with_normals=True)
        return d / noise.subset(sel).sigma_for(n)

    everything = np.ones(len(pts), dtype=bool)
    for it in range(params.fit_iterations):
        sel = keep.copy()
        starts = guesses if it == 0 else [best_x]
        results = []
        for x0 in starts:
            x0 = np.clip(x0, lo + 1e-6, hi - 1e-6)
            results.append(least_squares(lambda x, m=sel: scaled(x, m), x0, bounds=(lo, hi), method="trf", max_nfev=60))
        best_x = min(results, key=lambda r: float(np.sum(r.fun**2))).x
        r = scaled(best_x, everything)
        rms = float(np.sqrt(np.mean(r[keep] ** 2)))
        metric = np.abs(model_distance(shape, best_x, pts))
        new_keep = (np.abs(r) <= params.outlier_sigma * rms) | (metric <= params.outlier_floor_m)
        if new_keep.sum() < 5 or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    assert best_x is not None
    return best_x, keep


_N_PARAMS: dict[str, int] = {"hemispheroid": 4, "semi_ellipsoid": 6, "cone": 6, "tetrahedron": 6}


def selection_criterion(rms: float, n_points: int, n_params: int, params: RockParams = RockParams()) -> float:
    """BIC of a fit, ``n ln(rms^2) + k ln(n)``, with ``n = n_points / selection_points_per_sample`` independent
    residuals (at least 2); lower is better. Compare models of one rock by the same ``n_points``."""
    n = max(n_points / params.selection_points_per_sample, 2.0)
    return n * math.log(max(rms, 1e-12) ** 2) + n_params * math.log(n)


def fit_best_model(
    points: np.ndarray,
    plane: LocalPlane,
    peak_xyz: np.ndarray,
    height_m: float,
    params: RockParams = RockParams(),
    shapes: tuple[RockShape, ...] = ROCK_SHAPES,
    ground: np.ndarray | None = None,
    sensor_xyz: np.ndarray | None = None,
) -> tuple[RockModel, dict[str, RockModel]] | None:
    """Step 4: fit every model to the rock's surface points and keep the one with the lowest RMS.

    ``ground`` (optional) are ground points around the rock (inside the grown region's radius but not above the
    plane): outside its footprint a model is the ground plane, so they pin the footprint's edge without entering
    the RMS, which is over the rock's surface points only. With ``sensor_xyz`` (the cameras) the fits weigh each
    point by its stereo noise for the surface (:class:`PointNoise`) and the models are compared by that normalised
    RMS; ``RockModel.rms_m`` is always in metres.

    Selection departs from the paper's "lowest RMS": the models differ in their number of parameters (hemispheroid
    4, the others 6) and the hemispheroid is nested in the semi-ellipsoid (equal axes), which therefore fits it at
    least as well (up to outlier removal); and stereo points are correlated, so the richer models also fit
    correlated stereo error and the facets of one-sided, range-smeared views. The kept model minimises a Bayesian
    information criterion over the rock's inlier residuals, ``n ln(RMS^2) + k ln(n)`` with ``n`` the rock's points
    as fitted (thinned to ``max_points_per_fit``) over ``selection_points_per_sample`` (the points per independent
    residual). Between the three 6-parameter models this is the lowest RMS, as in the paper.
    """
    rng = np.random.default_rng(0)
    p = np.asarray(points, dtype=float)
    if len(p) > params.max_points_per_fit:
        p = p[rng.choice(len(p), params.max_points_per_fit, replace=False)]
    g = np.zeros((0, 3)) if ground is None else np.asarray(ground, dtype=float)
    if len(g) > params.max_points_per_fit // 2:
        g = g[rng.choice(len(g), params.max_points_per_fit // 2, replace=False)]
    R = plane.basis()
    foot = peak_xyz - plane.height_of(peak_xyz[None])[0] * plane.normal
    world = np.vstack([p, g])
    local = (world - foot) @ R
    is_rock = np.r_[np.ones(len(p), bool), np.zeros(len(g), bool)]
    noise = None
    if sensor_xyz is not None and params.noise_weighted_fit:
        ray = world - np.asarray(sensor_xyz, dtype=float)
        rng = np.linalg.norm(ray, axis=1)
        noise = PointNoise(
            (ray / np.maximum(rng, 1e-9)[:, None]) @ R,
            params.fit_sigma_floor_m + params.range_sigma_per_m2 * rng * rng,
            params.fit_sigma_floor_m + params.angular_sigma_rad * rng,
        )
    models: dict[str, RockModel] = {}
    scores: dict[str, float] = {}
    for shape in shapes:
        fit = fit_rock_model(shape, local, height_m, params, noise)
        if fit is None:
            continue
        x, keep = fit
        inl = keep & is_rock
        if inl.sum() < 3:
            continue
        d, n = model_distance(shape, x, local[inl], with_normals=True)
        rms = float(np.sqrt(np.mean(d**2)))
        scores[shape] = rms if noise is None else float(np.sqrt(np.mean((d / noise.subset(inl).sigma_for(n)) ** 2)))
        cx, cy, a, b, h, yaw = _model_parts(shape, x)
        if shape in ("semi_ellipsoid", "cone") and a < b:  # canonical: the length is the longer axis
            a, b, yaw = b, a, yaw + 0.5 * math.pi
        yaw = (yaw + math.pi) % (2.0 * math.pi) - math.pi
        centre = foot + R @ np.array([cx, cy, 0.0])
        models[shape] = RockModel(shape, centre, 2 * a, 2 * b, h, yaw, rms, len(p), len(d), plane.normal.copy())
    if not models:
        return None

    def score(m: RockModel) -> float:
        return selection_criterion(scores[m.shape], m.n_points, _N_PARAMS[m.shape], params)

    best = min(models.values(), key=score)
    return best, models
