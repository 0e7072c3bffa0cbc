"""Steps 1-2 of GESTALT (Maimone et al. 2005, section 4.2): "Range images from stereo are converted to goodness
or traversability maps" - the world-fixed toroidal grid of per-cell range-point statistics ("the usual modulo
map indexing", :meth:`GoodnessMap.update`) and, per cell of the window round the rover, the least-squares
patch plane whose tilt, RMS residual and step give its goodness (:meth:`GoodnessMap.evaluate`), the step taken
with each peak's top raised by what stereo loses at it (:func:`apex_lift_m`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from nav.gestalt.params import GestaltParams

# moments binned per cell, offsets (dx, dy) from the cell centre, z world elevation
_MOMENTS = ("n", "dx", "dy", "z", "dxdx", "dxdy", "dydy", "dxz", "dyz", "zz")
_NO_CELL = np.iinfo(np.int64).min
# a peak needs this many known neighbours (of 8) for the apex correction: a cone seen from one side has its front
# and flanks (5); the corner of a region of data on a tilted plane has 3
_APEX_MIN_NEIGHBOURS = 4


# ----------------------------------------------------------------------------------------------------------------
# Goodness map
# ----------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GoodnessWindow:
    """The evaluated map around the rover. Arrays are indexed ``[i, j]`` = world cell ``(ix0 + i, iy0 + j)``.

    (Axis 0 runs east along world x, axis 1 north along world y; transpose for a north-up image.)
    """

    origin_cell: tuple[int, int]  # world cell index (ix0, iy0) of element [0, 0]
    cell_size_m: float
    goodness: np.ndarray  # in [0, 1]; 0 impassable; NaN unknown
    elevation_m: np.ndarray  # height of the patch plane at the cell centre (world z); NaN unknown
    tilt_deg: np.ndarray  # NaN unknown
    roughness_m: np.ndarray  # RMS residual about the patch plane; NaN unknown
    step_m: np.ndarray  # spread of the patch's elevations about its plane; NaN unknown
    point_count: np.ndarray  # range points in the cell itself (int)
    range_m: np.ndarray | None = None  # distance from the rover at which the cell's data was taken; NaN unknown

    @property
    def shape(self) -> tuple[int, int]:
        return self.goodness.shape

    def cell_centres_xy(self) -> np.ndarray:
        """(n, n, 2) world (x, y) of the cell centres."""
        i, j = np.indices(self.shape)
        cs = self.cell_size_m
        return np.stack([(self.origin_cell[0] + i + 0.5) * cs, (self.origin_cell[1] + j + 0.5) * cs], axis=-1)

    def cell_index(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Window indices (i, j) of world points (N, 2) and whether each lies inside the window."""
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        i = np.floor(xy[:, 0] / self.cell_size_m).astype(np.int64) - self.origin_cell[0]
        j = np.floor(xy[:, 1] / self.cell_size_m).astype(np.int64) - self.origin_cell[1]
        inside = (i >= 0) & (i < self.shape[0]) & (j >= 0) & (j < self.shape[1])
        return i, j, inside

    def goodness_at(self, xy: np.ndarray) -> np.ndarray:
        """Goodness at world points (N, 2); NaN where unknown or outside the window."""
        i, j, inside = self.cell_index(xy)
        out = np.full(len(i), np.nan)
        out[inside] = self.goodness[i[inside], j[inside]]
        return out


class GoodnessMap:
    """World-fixed toroidal grid of per-cell range-point statistics (paper: "modulo map indexing").

    World cell ``(ix, iy) = floor((x, y) / cell_size_m)`` lives in slot ``(ix mod N, iy mod N)``; each slot also
    stores the cell index it holds, so a slot last written for a cell one map-width away reads as unknown rather
    than as stale terrain. ``N`` covers the window plus the plane-fit margin, so no scrolling is ever needed.
    """

    def __init__(self, params: GestaltParams = GestaltParams()) -> None:
        self.params = params
        self.slots = params.window_cells + 2 * params.patch_cells + 2
        n = self.slots
        self.cell_ix = np.full((n, n), _NO_CELL, np.int64)
        self.cell_iy = np.full((n, n), _NO_CELL, np.int64)
        self.moments = np.zeros((len(_MOMENTS), n, n))
        # z_min, its dx, dy from the cell centre; z_max, its dx, dy
        self.extremes = np.zeros((6, n, n))
        self.obs_range = np.full((n, n), np.inf)  # distance from the rover at which each slot's data was taken

    def _trim_count(self, n: np.ndarray) -> np.ndarray:
        """How many of a cell's ``n`` points to skip at each end when taking its extreme elevations."""
        p = self.params
        return np.minimum(np.floor(p.extreme_trim_fraction * n), (n - 1) // 2).astype(np.int64)

    def _rover_cell(self, rover_xy: np.ndarray) -> tuple[int, int]:
        cs = self.params.cell_size_m
        return int(np.floor(rover_xy[0] / cs)), int(np.floor(rover_xy[1] / cs))

    def update(self, points_world: np.ndarray, rover_xy: np.ndarray) -> int:
        """Step 1: bin one range image's world points; cells it sees replace their old contents. Returns cells hit.

        Points farther than the map reaches from ``rover_xy`` (about half a map width) are ignored; NaN rows too.
        """
        cs = self.params.cell_size_m
        pts = np.asarray(points_world, dtype=float).reshape(-1, 3)
        x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
        rover_xy = np.asarray(rover_xy, dtype=float)
        rx, ry = self._rover_cell(rover_xy)
        half = (self.slots - 1) // 2
        with np.errstate(invalid="ignore"):
            fx = np.floor(x / cs)
            fy = np.floor(y / cs)
            keep = (np.abs(fx - rx) <= half) & (np.abs(fy - ry) <= half) & np.isfinite(z)  # NaN compares False
        x, y, z = x[keep], y[keep], z[keep]
        ix, iy = fx[keep].astype(np.int64), fy[keep].astype(np.int64)
        side = 2 * half + 1
        local = (ix - rx + half) * side + (iy - ry + half)
        dx = x - (ix + 0.5) * cs
        dy = y - (iy + 0.5) * cs
        weights = {"dx": dx, "dy": dy, "z": z, "dxdx": dx * dx, "dxdy": dx * dy, "dydy": dy * dy}
        weights |= {"dxz": dx * z, "dyz": dy * z, "zz": z * z}
        count = np.bincount(local, minlength=side * side)
        hit = np.flatnonzero(count)
        batch = np.empty((len(_MOMENTS), hit.size))
        batch[0] = count[hit]
        for k, name in enumerate(_MOMENTS[1:], start=1):
            batch[k] = np.bincount(local, weights=weights[name], minlength=side * side)[hit]
        # per-cell extreme elevations and where in the cell they are (for the plane-relative step): the k-th
        # lowest and k-th highest point, k growing with the cell's count, so a lone stereo mismatch is not a rock
        z_span = float(np.ptp(z)) if z.size else 0.0
        order = np.argsort(local + 0.5 * (z - (z.min() if z.size else 0.0)) / (z_span + 1e-9))  # by cell, then z
        start = np.cumsum(count[hit]) - count[hit]
        k = self._trim_count(count[hit])
        lo = order[start + k]
        hi = order[start + count[hit] - 1 - k]
        extremes = np.stack([z[lo], dx[lo], dy[lo], z[hi], dx[hi], dy[hi]])
        cell_x = hit // side - half + rx
        cell_y = hit % side - half + ry
        sx, sy = cell_x % self.slots, cell_y % self.slots
        rng = np.hypot((cell_x + 0.5) * cs - rover_xy[0], (cell_y + 0.5) * cs - rover_xy[1])
        # newer data overwrites older (paper) unless the older was taken from much closer (stereo error grows
        # with range squared: a far, noisy look must not erase a near one)
        stale = (self.cell_ix[sx, sy] != cell_x) | (self.cell_iy[sx, sy] != cell_y)
        slack = self.params.keep_closer_slack_m
        take = np.ones_like(stale) if slack is None else stale | (rng <= self.obs_range[sx, sy] + slack)
        frac = self.params.keep_denser_fraction
        if frac is not None:
            take &= stale | (batch[0] >= frac * self.moments[0, sx, sy])
        sx, sy = sx[take], sy[take]
        self.cell_ix[sx, sy] = cell_x[take]
        self.cell_iy[sx, sy] = cell_y[take]
        self.moments[:, sx, sy] = batch[:, take]
        self.extremes[:, sx, sy] = extremes[:, take]
        self.obs_range[sx, sy] = rng[take]
        return int(take.sum())

    def _gather(self, ix0: int, iy0: int, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Moments, extremes and observation ranges of world cells ``[ix0, ix0 + size) x [iy0, iy0 + size)``.

        Cells never seen (or whose slot holds another cell) have zero moments, z_min = +inf, z_max = -inf and a
        NaN range.
        """
        cx = np.arange(ix0, ix0 + size)
        cy = np.arange(iy0, iy0 + size)
        sx, sy = np.ix_(cx % self.slots, cy % self.slots)
        current = (self.cell_ix[sx, sy] == cx[:, None]) & (self.cell_iy[sx, sy] == cy[None, :])
        moments = np.where(current, self.moments[:, sx, sy], 0.0)
        extremes = self.extremes[:, sx, sy]
        extremes[0] = np.where(current, extremes[0], np.inf)
        extremes[3] = np.where(current, extremes[3], -np.inf)
        return moments, extremes, np.where(current, self.obs_range[sx, sy], np.nan)

    def evaluate(self, rover_xy: np.ndarray) -> GoodnessWindow:
        """Step 2: tilt, roughness, step and goodness of every cell of the window centred on the rover."""
        p = self.params
        n, m, cs = p.window_cells, p.patch_cells, p.cell_size_m
        rx, ry = self._rover_cell(np.asarray(rover_xy, dtype=float))
        ix0, iy0 = rx - n // 2, ry - n // 2
        moments, extremes, obs_range = self._gather(ix0 - m, iy0 - m, n + 2 * m)
        fit = fit_patch_planes(moments, p)
        inner = (slice(m, m + n), slice(m, m + n))
        a, b, c = (arr[inner] for arr in fit[:3])
        tilt_deg = np.degrees(np.arctan(np.hypot(a, b)))
        roughness_m = fit[3][inner]
        lift = apex_lift_m(extremes, obs_range, p)
        if lift is not None:
            extremes = extremes.copy()
            extremes[3] = extremes[3] + lift
        step_m = patch_step_m(extremes, a, b, c, p)
        count = moments[0][inner]
        known = fit[4][inner] & (count >= p.min_points_per_cell)
        goodness = goodness_from(tilt_deg, roughness_m, step_m, p)
        unknown = np.where(known, 1.0, np.nan)
        return GoodnessWindow(
            origin_cell=(ix0, iy0),
            cell_size_m=cs,
            goodness=goodness * unknown,
            elevation_m=c * unknown,
            tilt_deg=tilt_deg * unknown,
            roughness_m=roughness_m * unknown,
            step_m=step_m * unknown,
            point_count=count.astype(np.int64),
            range_m=obs_range[inner] * unknown,
        )


def _patch_kernels(params: GestaltParams) -> dict[str, np.ndarray]:
    """Disc kernel over cell offsets, and its products with the offsets (metres) for the moment shifts."""
    m, cs = params.patch_cells, params.cell_size_m
    o = np.arange(-m, m + 1) * cs
    ox, oy = np.meshgrid(o, o, indexing="ij")  # axis 0 = x, axis 1 = y
    disc = (ox**2 + oy**2 <= params.patch_radius_m**2 + 1e-12).astype(np.float64)
    return {"1": disc, "x": disc * ox, "y": disc * oy, "xx": disc * ox * ox, "xy": disc * ox * oy, "yy": disc * oy * oy}


def fit_patch_planes(moments: np.ndarray, params: GestaltParams) -> tuple[np.ndarray, ...]:
    """Least-squares plane ``z = a x + b y + c`` through the points within ``patch_radius_m`` of each cell centre.

    ``moments`` are the per-cell sums of ``_MOMENTS`` (offsets from each cell's own centre). A neighbour cell at
    offset ``o`` contributes its sums shifted to the target cell's centre, e.g. ``sum (dx + o_x)^2 = S_dxdx +
    2 o_x S_dx + o_x^2 n``; each term is one correlation of a moment image with the disc kernel times a power of
    the offset. Returns ``(a, b, c, rms_residual_m, ok)`` per cell, ``c`` the plane height at the cell centre and
    ``ok`` False where the patch has too few points or they do not span the plane.
    """
    k = _patch_kernels(params)
    M = dict(zip(_MOMENTS, moments, strict=True))

    def corr(img: np.ndarray, kernel: str) -> np.ndarray:
        return cv2.filter2D(img, cv2.CV_64F, k[kernel], borderType=cv2.BORDER_CONSTANT)

    n = corr(M["n"], "1")
    sx = corr(M["dx"], "1") + corr(M["n"], "x")
    sy = corr(M["dy"], "1") + corr(M["n"], "y")
    sz = corr(M["z"], "1")
    sxx = corr(M["dxdx"], "1") + 2 * corr(M["dx"], "x") + corr(M["n"], "xx")
    syy = corr(M["dydy"], "1") + 2 * corr(M["dy"], "y") + corr(M["n"], "yy")
    sxy = corr(M["dxdy"], "1") + corr(M["dx"], "y") + corr(M["dy"], "x") + corr(M["n"], "xy")
    sxz = corr(M["dxz"], "1") + corr(M["z"], "x")
    syz = corr(M["dyz"], "1") + corr(M["z"], "y")
    szz = corr(M["zz"], "1")
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_n = np.where(n > 0, 1.0 / n, 0.0)
        mx, my, mz = sx * inv_n, sy * inv_n, sz * inv_n
        cxx, cyy, cxy = sxx * inv_n - mx * mx, syy * inv_n - my * my, sxy * inv_n - mx * my
        cxz, cyz, czz = sxz * inv_n - mx * mz, syz * inv_n - my * mz, szz * inv_n - mz * mz
        det = cxx * cyy - cxy * cxy
        # points must spread over at least a cell's width in every direction (smallest covariance eigenvalue)
        lam_min = 0.5 * (cxx + cyy) - np.sqrt(0.25 * (cxx - cyy) ** 2 + cxy**2)
        ok = (n >= params.min_points_patch) & (lam_min >= params.cell_size_m**2 / 12.0)
        safe_det = np.where(ok, det, 1.0)
        a = np.where(ok, (cxz * cyy - cyz * cxy) / safe_det, 0.0)
        b = np.where(ok, (cyz * cxx - cxz * cxy) / safe_det, 0.0)
    c = mz - a * mx - b * my
    rms = np.sqrt(np.maximum(czz - a * cxz - b * cyz, 0.0))
    return a, b, c, rms, ok


def apex_lift_m(extremes: np.ndarray, obs_range_m: np.ndarray, params: GestaltParams) -> np.ndarray | None:
    """Height that stereo lost at the top of each peak, per cell: flank slope times the matching window's reach.

    A correlation window straddling a depth edge matches the farther surface or fails a check, so area stereo
    loses up to half a window at an object's border (Hirschmueller, Innocent & Garibaldi 2002, "Real-time
    correlation-based stereo vision with reduced border errors", IJCV 47); this pipeline's depth-edge check and blob
    filter then drop what is left of a rock's narrow top. On a cone or tetrahedron that is the apex: stereo reads
    a 25-29 cm rock's top 8-13 cm low (``docs/navigation/autonav-tall-rocks.md``). The lost half-window spans
    ``apex_reach_rad * range`` on the ground, over which the rock keeps rising at its flank slope; so at a cell
    whose (trimmed) top is higher than every known neighbour's top (at least ``_APEX_MIN_NEIGHBOURS`` of the 8
    known: the ground behind a rock is in its shadow), the top is raised by ``s * apex_reach_rad * range``: ``s``
    the median slope from it down to those neighbours' tops, capped at ``apex_max_slope``; ``range`` the distance
    from which the cell was seen. A dome's or a ledge's top is flat (small ``s``), a cone's steep; on a clean
    plane no cell with that many neighbours is a peak. ``extremes`` and ``obs_range_m`` as
    :meth:`GoodnessMap._gather` returns them (unknown: top -inf, range NaN). None when ``apex_reach_rad`` is None
    (off).
    """
    p = params
    if p.apex_reach_rad is None:
        return None
    top = extremes[3]
    n0, n1 = top.shape
    padded = np.pad(top, 1, constant_values=-np.inf)
    slopes = np.full((8, n0, n1), np.nan)
    peak = np.isfinite(top)
    k = 0
    for ox in (-1, 0, 1):
        for oy in (-1, 0, 1):
            if ox == 0 and oy == 0:
                continue
            nb = padded[1 + ox : 1 + ox + n0, 1 + oy : 1 + oy + n1]
            known = np.isfinite(nb) & np.isfinite(top)
            drop = np.where(known, top - np.where(known, nb, 0.0), np.nan)
            peak &= ~(drop < 0)
            slopes[k] = drop / (p.cell_size_m * np.hypot(ox, oy))
            k += 1
    count = np.isfinite(slopes).sum(axis=0)
    # median of the known neighbours' slopes (NaN sorts last)
    ordered = np.sort(slopes, axis=0)
    lo = np.take_along_axis(ordered, np.maximum((count - 1) // 2, 0)[None], axis=0)[0]
    hi = np.take_along_axis(ordered, np.maximum(count // 2, 0)[None], axis=0)[0]
    slope = np.clip(np.where(count > 0, 0.5 * (lo + hi), 0.0), 0.0, p.apex_max_slope)
    lift = slope * p.apex_reach_rad * np.nan_to_num(obs_range_m, nan=0.0)
    return np.where(peak & (count >= _APEX_MIN_NEIGHBOURS), lift, 0.0)


def patch_step_m(
    extremes: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, params: GestaltParams
) -> np.ndarray:
    """Spread of the patch's elevations about its plane: max(z - plane) - min(z - plane) over the disc.

    Paper: "minimum and maximum elevation difference from the best fit plane". A disc-shaped max/min filter over
    the neighbours' extreme points, each taken relative to the target cell's plane at that point's position, so a
    clean plane of any tilt has step 0 and a 30 cm ledge anywhere in the patch has step ~0.3 m. ``extremes``
    (z_min, its dx, dy, z_max, its dx, dy per cell) covers the window plus a ``patch_cells`` margin; ``a, b, c``
    the window.
    """
    m, cs = params.patch_cells, params.cell_size_m
    n = a.shape[0]
    above = np.full(a.shape, -np.inf)
    below = np.full(a.shape, np.inf)
    for ox in range(-m, m + 1):
        for oy in range(-m, m + 1):
            if (ox * ox + oy * oy) * cs * cs > params.patch_radius_m**2 + 1e-12:
                continue
            nb = extremes[:, m + ox : m + ox + n, m + oy : m + oy + n]
            low = nb[0] - (a * (ox * cs + nb[1]) + b * (oy * cs + nb[2]) + c)
            high = nb[3] - (a * (ox * cs + nb[4]) + b * (oy * cs + nb[5]) + c)
            np.maximum(above, high, out=above)
            np.minimum(below, low, out=below)
    with np.errstate(invalid="ignore"):
        spread = above - below
    return np.where(np.isfinite(spread), spread, np.nan)


def goodness_from(
    tilt_deg: np.ndarray, roughness_m: np.ndarray, step_m: np.ndarray, params: GestaltParams
) -> np.ndarray:
    """Goodness in [0, 1]: per factor 1 at or below its benign value, 0 at or beyond its limit; the worst factor."""

    def ramp(x: np.ndarray, benign: float, limit: float) -> np.ndarray:
        return np.clip((limit - x) / (limit - benign), 0.0, 1.0)

    p = params
    g = np.minimum(
        ramp(tilt_deg, p.benign_tilt_deg, p.max_tilt_deg), ramp(roughness_m, p.benign_roughness_m, p.max_roughness_m)
    )
    return np.minimum(g, ramp(step_m, p.benign_step_m, p.max_step_m))
