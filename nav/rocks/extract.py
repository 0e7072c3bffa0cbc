"""Steps 1-3 of rock-based localisation (Li et al., REFERENCE.md section 5) - rock peaks, the local plane and
rock height, region growing - and :func:`extract_rocks`, which runs steps 1-4 in order on one site's points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from nav.rocks.models import fit_best_model
from nav.rocks.params import ExtractedRock, LocalPlane, RockParams, RockPeak

# ================================================================================================================
# Step 1: rock peaks
# ================================================================================================================


def extract_peaks(points: np.ndarray, params: RockParams = RockParams()) -> list[RockPeak]:
    """Step 1: local height maxima in a ``peak_window_m`` window with a height range and enough points.

    The points are binned on a ``grid_cell_m`` grid; a cell's top is its ``top_rank``-th highest point and its
    bottom the ``top_rank``-th lowest, so one stray point makes neither a peak nor a range. A cell is a peak when
    its top is the highest top of the window centred on it, the window's top minus its lowest bottom is at least
    ``min_height_range_m`` and the window holds ``min_window_points`` points. Highest peaks first.
    """
    from scipy.ndimage import maximum_filter, minimum_filter, uniform_filter

    p = np.asarray(points, dtype=float)
    k = params.top_rank
    if len(p) < params.min_window_points:
        return []
    cell = params.grid_cell_m
    origin = p[:, :2].min(axis=0)
    ij = np.floor((p[:, :2] - origin) / cell).astype(np.int64)
    shape = tuple(ij.max(axis=0) + 1)
    flat = ij[:, 0] * shape[1] + ij[:, 1]
    order = np.lexsort((p[:, 2], flat))
    flat_sorted = flat[order]
    starts = np.flatnonzero(np.r_[True, flat_sorted[1:] != flat_sorted[:-1]])
    counts = np.diff(np.r_[starts, len(flat_sorted)])
    cells = flat_sorted[starts]
    count = np.zeros(shape)
    count.flat[cells] = counts
    enough = counts >= k
    starts, counts, cells = starts[enough], counts[enough], cells[enough]
    top_idx = order[starts + counts - k]  # k-th highest point of each cell
    bottom_idx = order[starts + k - 1]  # k-th lowest
    top = np.full(shape, -np.inf)
    bottom = np.full(shape, np.inf)
    top_point = np.full(shape, -1, dtype=np.int64)
    top.flat[cells] = p[top_idx, 2]
    bottom.flat[cells] = p[bottom_idx, 2]
    top_point.flat[cells] = top_idx
    # a cell's support: the median top of its 3 x 3 neighbourhood (empty cells excluded), so a lone streak or a
    # stray cell never outranks a rock's top
    shifted = np.full((9, *shape), np.nan)
    padded = np.pad(np.where(np.isfinite(top), top, np.nan), 1, constant_values=np.nan)
    for n, (di, dj) in enumerate((di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1)):
        shifted[n] = padded[1 + di : 1 + di + shape[0], 1 + dj : 1 + dj + shape[1]]
    n_valid = np.isfinite(shifted).sum(axis=0)
    ordered = np.sort(shifted, axis=0)  # NaN sorts last
    lo_idx, hi_idx = np.maximum(n_valid - 1, 0) // 2, n_valid // 2
    median = 0.5 * (np.take_along_axis(ordered, lo_idx[None], 0)[0] + np.take_along_axis(ordered, hi_idx[None], 0)[0])
    support = np.where((n_valid >= 3) & np.isfinite(top), median, -np.inf)
    w = max(1, int(round(params.peak_window_m / cell)))
    w += 1 - w % 2  # odd window centred on the cell
    # the apex: the highest cell top of the 3 x 3 neighbourhood (a pointed rock's top cell outranks its neighbours
    # by far more than their median does, so the support cell may be next to it)
    apex_top, apex_point = top.copy(), top_point.copy()
    padded_top = np.pad(top, 1, constant_values=-np.inf)
    padded_idx = np.pad(top_point, 1, constant_values=-1)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            t = padded_top[1 + di : 1 + di + shape[0], 1 + dj : 1 + dj + shape[1]]
            higher = t > apex_top
            apex_top[higher] = t[higher]
            apex_point[higher] = padded_idx[1 + di : 1 + di + shape[0], 1 + dj : 1 + dj + shape[1]][higher]
    win_top = maximum_filter(support, size=w, mode="constant", cval=-np.inf)
    win_bottom = minimum_filter(bottom, size=w, mode="constant", cval=np.inf)
    win_count = uniform_filter(count, size=w, mode="constant") * (w * w)
    # the paper's height range: the window's highest point (robust: its k-th highest) above its lowest
    win_range = maximum_filter(top, size=w, mode="constant", cval=-np.inf) - win_bottom
    is_peak = (
        np.isfinite(support)
        & (support >= win_top)
        & (win_range >= params.min_height_range_m)
        & (win_count >= params.min_window_points - 0.5)
    )
    cells = np.flatnonzero(is_peak.ravel())
    ranges, counts = win_range.flat[cells], np.rint(win_count.flat[cells]).astype(int)
    peaks = [
        RockPeak(p[apex_point.flat[c]].copy(), float(h), int(n)) for c, h, n in zip(cells, ranges, counts, strict=True)
    ]
    peaks.sort(key=lambda pk: -pk.xyz_m[2])
    return peaks


# ================================================================================================================
# Step 2: local plane and rock height
# ================================================================================================================


def fit_plane_robust(points: np.ndarray, params: RockParams = RockParams()) -> LocalPlane | None:
    """Least-squares plane ``z = a x + b y + c`` through the ground points of a window (rock points rejected).

    Rock points are one-sided (positive) outliers of the ground and may be most of a window (and stereo leaves
    streaks of mixed-depth points behind rocks), so the fit starts from the lower envelope (three fits to the lowest
    40 % of the points about the previous plane) and then refits, each time keeping the points below
    ``plane_clip_sigma`` robust sigmas above the plane (and above -4 sigma, for stray points below). The ground
    noise sigma is the spread of the lower half of the kept points' residuals. ``None`` with fewer than 6 points.
    """
    p = np.asarray(points, dtype=float)
    if len(p) < 6:
        return None
    centre = p.mean(axis=0)
    q = p - centre
    A_all = np.column_stack([q[:, 0], q[:, 1], np.ones(len(q))])
    coef = np.zeros(3)
    for _ in range(3):  # lower envelope first: the lowest 40 % of the points about the current plane
        r = q[:, 2] - A_all @ coef
        keep = r <= np.percentile(r, 40.0)
        coef, *_ = np.linalg.lstsq(A_all[keep], q[keep, 2], rcond=None)
    sigma = 0.0
    for _ in range(params.plane_iterations):
        coef, *_ = np.linalg.lstsq(A_all[keep], q[keep, 2], rcond=None)
        r = q[:, 2] - A_all @ coef
        lower = r[r <= np.median(r[keep])]  # the lower half is rock-free: its spread is the ground noise
        sigma = max(1.4826 * float(np.median(np.abs(lower - np.median(r[keep])))), 1e-4)
        new_keep = (r < params.plane_clip_sigma * sigma) & (r > -4.0 * sigma)
        if new_keep.sum() < 6 or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    n = np.array([-coef[0], -coef[1], 1.0])
    scale = np.linalg.norm(n)
    n /= scale
    offset = float(n @ (centre + np.array([0.0, 0.0, coef[2]])))
    return LocalPlane(n, offset, sigma / scale, int(keep.sum()))


def fit_local_plane(
    tree: cKDTree, points: np.ndarray, peak: RockPeak, params: RockParams = RockParams()
) -> tuple[LocalPlane, float] | None:
    """Step 2: the local plane around a peak and the rock height (the peak's distance to it).

    The window is ``plane_radius_m`` first, widened to ``plane_radius_h * h`` for tall rocks so it reaches well
    past the rock's foot (region growing stops at 1.7 h).
    """
    radius = params.plane_radius_m
    plane, height = None, 0.0
    for _ in range(2):
        idx = tree.query_ball_point(peak.xyz_m[:2], radius)
        plane = fit_plane_robust(points[idx], params)
        if plane is None:
            return None
        height = float(plane.height_of(peak.xyz_m[None])[0])
        if params.plane_radius_h * height <= radius:
            break
        radius = params.plane_radius_h * height
    assert plane is not None
    return plane, height


# ================================================================================================================
# Step 3: region growing
# ================================================================================================================


def grow_rock_region(
    points: np.ndarray, peak: RockPeak, plane: LocalPlane, height_m: float, params: RockParams = RockParams()
) -> np.ndarray:
    """Step 3 (the paper's local search): indices into ``points`` of the rock's surface points.

    Candidates are points above the plane (by ``candidate_clearance_m`` and 1.5 ground sigmas) within 1.7 h of the
    peak (horizontally). 1) Take the candidates within 0.3 h of the peak; ``maxD`` is the largest distance from one
    of them to its nearest candidate neighbour. 2) From each point added in the last step, add the candidates within
    ``maxD``; the search radius grows by ``maxD``. Repeat until the radius reaches 1.7 h or nothing is added.
    """
    p = np.asarray(points, dtype=float)
    r_stop = params.grow_stop_h * height_m
    horiz = np.hypot(p[:, 0] - peak.xyz_m[0], p[:, 1] - peak.xyz_m[1])
    clearance = max(params.candidate_clearance_m, 1.5 * plane.sigma_m)
    cand = np.flatnonzero((horiz <= r_stop) & (plane.height_of(p) >= clearance))
    if len(cand) < 2:
        return cand
    cp = p[cand]
    tree = cKDTree(cp)
    start = np.flatnonzero(horiz[cand] <= params.grow_start_h * height_m)
    if len(start) == 0:
        start = np.array([int(np.argmin(horiz[cand]))])
    nn_d, _ = tree.query(cp[start], k=2)
    max_d = float(np.clip(nn_d[:, 1].max(), params.min_step_m, params.max_step_m))
    member = np.zeros(len(cand), dtype=bool)
    member[start] = True
    frontier = start
    radius = params.grow_start_h * height_m
    while radius < r_stop and len(frontier):
        found = tree.query_ball_point(cp[frontier], max_d)
        hits = np.unique(np.concatenate([np.asarray(f, dtype=np.int64) for f in found]))
        frontier = hits[~member[hits]]
        member[frontier] = True
        radius += max_d
    return cand[member]


# ================================================================================================================
# The extraction pipeline
# ================================================================================================================


def extract_rocks(
    points: np.ndarray, params: RockParams = RockParams(), sensor_xyz: np.ndarray | None = None
) -> list[ExtractedRock]:
    """Rocks of one site from its dense ground points (N, 3): the paper's steps 1-4 in order.

    Peaks are taken highest first. A peak near an already extracted rock is that rock again (stereo range noise
    smears a distant rock along the line of sight into several local maxima): the gate is
    ``duplicate_radius_m`` plus half the rock's length across the line of sight from ``sensor_xyz`` (the
    cameras' position, if given), widened by three range sigmas along it.
    """
    p = np.asarray(points, dtype=float)
    p = p[np.isfinite(p).all(axis=1)]
    tree2d = cKDTree(p[:, :2])
    rocks: list[ExtractedRock] = []
    taken = np.zeros(len(p), dtype=bool)
    for peak in extract_peaks(p, params):  # 1. peaks
        if taken[tree2d.query(peak.xyz_m[:2])[1]] or _duplicate(peak.xyz_m, rocks, sensor_xyz, params):
            continue
        local = fit_local_plane(tree2d, p, peak, params)  # 2. local plane, rock height
        if local is None:
            continue
        plane, height = local
        if height < max(params.min_rock_height_m, params.min_height_sigma * plane.sigma_m):
            continue
        near = np.asarray(tree2d.query_ball_point(peak.xyz_m[:2], params.grow_stop_h * height + 1e-6), dtype=np.int64)
        region = near[grow_rock_region(p[near], peak, plane, height, params)]  # 3. region growing
        region = region[~taken[region]]
        if len(region) < params.min_region_points:
            continue
        dist = np.hypot(*(p[near, :2] - peak.xyz_m[:2]).T)  # 4. models, the ground around pinning the footprint
        reach = float(np.hypot(*(p[region, :2] - peak.xyz_m[:2]).T).max()) + 2.0 * params.grid_cell_m
        ring = np.setdiff1d(near[(dist <= reach) & (plane.height_of(p[near]) < 0.5 * height)], region)
        fit = fit_best_model(p[region], plane, peak.xyz_m, height, params, ground=p[ring], sensor_xyz=sensor_xyz)
        if fit is None:
            continue
        model, models = fit
        taken[region] = True
        tie = top_point(p[region], plane, params) if params.tie_point == "top_median" else None
        rocks.append(ExtractedRock(peak, plane, height, p[region], model, models, tie))
    return rocks


@dataclass(frozen=True)
class RockObservation:
    """How well one site's points show a rock: the estimator's own data, no ground truth."""

    n_points: int  # the rock's surface points
    coverage_deg: float  # azimuth span of those points about the model's apex (10 deg bins)
    noise_frac: float  # stereo range sigma at the rock's range over its height

    def well_observed(self, params: RockParams = RockParams()) -> bool:
        """Enough points, around enough of the rock, with a range noise small next to its height.

        The models differ by a few centimetres on a 20-30 cm rock, so their type can only be told apart when the
        range noise (``k r^2``, 2.4 cm at 10 m, 9.6 cm at 20 m) is a small fraction of the height: 15 % (a 25 cm
        rock within about 12 m, a 40 cm rock within 16 m), over at least 180 degrees of azimuth and 200 points:
        with ``selection_points_per_sample`` = 32 points per independent residual, 200 points are about as many
        independent residuals as a 6-parameter model has parameters.
        """
        return (
            self.n_points >= params.well_observed_min_points
            and self.coverage_deg >= params.well_observed_min_coverage_deg
            and self.noise_frac <= params.well_observed_max_noise_frac
        )


def observation_quality(
    rock: ExtractedRock, sensor_xyz: np.ndarray, params: RockParams = RockParams()
) -> RockObservation:
    """Point count, azimuth coverage and relative range noise of an extracted rock seen from ``sensor_xyz``."""
    top = rock.model.top_xyz_m
    d = rock.points[:, :2] - top[:2]
    hist, _ = np.histogram(np.arctan2(d[:, 1], d[:, 0]), bins=36, range=(-math.pi, math.pi))
    rng = float(np.linalg.norm(top - np.asarray(sensor_xyz, dtype=float)))
    noise = params.range_sigma_per_m2 * rng * rng
    return RockObservation(len(rock.points), 10.0 * np.count_nonzero(hist), noise / max(rock.height_m, 1e-6))


def top_point(points: np.ndarray, plane: LocalPlane, params: RockParams = RockParams()) -> np.ndarray:
    """Median of a rock's points higher than ``tie_top_fraction`` of its highest point above the plane."""
    h = plane.height_of(points)
    return np.median(points[h >= params.tie_top_fraction * h.max()], axis=0)


def _duplicate(xyz: np.ndarray, rocks: list[ExtractedRock], sensor_xyz: np.ndarray | None, params: RockParams) -> bool:
    """Whether a peak falls in the gate of an extracted rock (see :func:`extract_rocks`)."""
    for r in rocks:
        m = r.model
        d = xyz[:2] - m.top_xyz_m[:2]
        across = params.duplicate_radius_m + 0.5 * max(m.length_m, m.width_m)
        if sensor_xyz is None:
            if np.hypot(*d) <= across:
                return True
            continue
        ray = m.top_xyz_m[:2] - np.asarray(sensor_xyz, dtype=float)[:2]
        rng = float(np.hypot(*ray))
        ray = ray / max(rng, 1e-9)
        along = across + 3.0 * params.range_sigma_per_m2 * rng * rng
        a, c = float(d @ ray), float(d[0] * -ray[1] + d[1] * ray[0])
        if (a / along) ** 2 + (c / across) ** 2 <= 1.0:
            return True
    return False
