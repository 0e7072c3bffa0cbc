"""GESTALT obstacle avoidance: goodness map, steering-arc votes, arbiter (Maimone et al. 2005, section 4.2).

"Range images from stereo are converted to goodness or traversability maps with 20 cm cells in a 10x10 m grid
centered on the rover. [...] planar patches centered on each map cell [...] each patch is a circle with the diameter
of the rover. The surface normal, RMS residual, and minimum and maximum elevation difference from the best fit plane
determine a goodness factor [...] Goodness maps [...] are registered and accumulated over time with the usual modulo
map indexing [...] new data overwrites the old [...] 23 forward arcs, 23 backward arcs, and two point turns [...]
adding up the goodness scores along each arc, with nearby cells given higher weight. [...] an arbiter, which also
takes input from waypoints."

One cycle, :meth:`GestaltPlanner.step`, reads as the paper's steps:

1. :meth:`GoodnessMap.update` - bin the world-frame range points into a world-fixed toroidal grid of per-cell point
   statistics (count, first and second moments, trimmed min/max elevation); cells seen in this image replace what
   was there, unless the old look was taken from much nearer (or held far more points): hazcam stereo error grows
   with range squared, and a rock at the edge of the view must not be erased by a glimpse of its flank.
2. :meth:`GoodnessMap.evaluate` - per cell of the 10 m window around the rover: least-squares plane through the
   points within ``patch_radius_m`` (summed moments of the neighbouring cells, one convolution per moment), giving
   tilt, RMS roughness and the step (spread of the min/max elevations about the plane); goodness 1 on benign ground
   falling linearly to 0 at any limit.
3. :func:`vote_arcs` - traversability vote per arc: weighted mean goodness over the rover's footprint (a rectangle)
   swept along the arc, nearer cells weighted more; an unknown or impassable cell met by the footprint's core
   within ``near_distance_m`` vetoes the arc; the lowest goodness the core meets is kept for the arbiter.
4. :func:`cost_to_go`, :func:`waypoint_votes` and :func:`arbitrate` - the goal's vote, then the best weighted sum of
   safe arcs, or none. The waypoint input is a path-cost field to the goal over the goodness window (Dijkstra;
   the MER flight software gained such a field in 2006, Carsten et al. 2007), so that an arc making progress along
   a detour round a rock outvotes one pointing straight at the goal behind it; near the goal the arc through the
   goal itself is driven (:func:`goal_arc`). Against dithering (GESTALT's classic failure: left-right-left, or
   forward-back-forward in front of a gap it cannot quite take) the arbiter penalises taking back the previous
   move (:func:`undoes`), the path walls off gaps narrower than the arcs can thread, and every cycle the rover
   stands somewhere makes the path there dearer (``GestaltPlanner.visits``).

Frames: world x east, y north, z up; poses are ``(x_m, y_m, yaw_rad)`` in the world, yaw about +z from +x. Arcs are
defined in the rover frame (x forward, y left). Pure: no drawing or logging; every result is returned as data.

Footprint sizes (see :class:`GestaltParams`): the paper's plane-fit patch is the whole rover (2.6 m diameter), which
grows every obstacle by the rover's radius, so arcs can be judged along their centre line. Here the patch is smaller
(0.6 m radius: about the wheel track's half-width, the wheels of a rover centred on the cell) so tilt and roughness
describe the ground under the wheels rather than a 5 m^2 average. Stereo at 256^2 reads rocks low (the SAD window
smooths their tops), so a rock is impassable only where the patch reaches its upper part: in practice goodness
grows a rock by ~0.35 m beyond its edge, not by the full patch radius. Vetoes therefore look at a core rectangle
(0.45 m x 0.4 m half-sizes) carried along the arc: the wheels' envelope plus a margin, less that growth; turning in
place, the core's corners sweep a disc. Votes average over the full footprint, so arcs passing obstacles with a
margin score better.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

# moments binned per cell, offsets (dx, dy) from the cell centre, z world elevation
_MOMENTS = ("n", "dx", "dy", "z", "dxdx", "dxdy", "dydy", "dxz", "dyz", "zz")
_NO_CELL = np.iinfo(np.int64).min


@dataclass(frozen=True)
class GestaltParams:
    """Every GESTALT threshold, with units. Paper values are marked "paper"; the rest say why."""

    # --- goodness map ---
    cell_size_m: float = 0.20  # paper
    map_size_m: float = 10.0  # paper: 10 x 10 m window centred on the rover
    # Radius of the plane-fit patch around each cell. Paper: the rover's diameter (2.6 m), i.e. 1.3 m; here 0.6 m
    # because arcs are scored over the swept footprint as well (module docstring).
    patch_radius_m: float = 0.6
    # A cell's data is replaced by a newer look only if that look is no more than this much farther away than the
    # one it replaces (None: always replace, as the paper).
    keep_closer_slack_m: float | None = 0.5
    # ... and only if it holds at least this fraction of the old look's points (a rock at the edge of the view, or
    # half hidden, must not erase a full look at it); None: no such rule
    keep_denser_fraction: float | None = 0.3
    min_points_per_cell: int = 3  # a cell with fewer own points is unknown
    min_points_patch: int = 20  # ... as is one whose patch holds fewer points
    # A cell's extreme elevations (for the step) skip this fraction of its points at each end: stereo mismatches
    # are isolated points; a rock is many.
    extreme_trim_fraction: float = 0.1
    # Goodness falls linearly from 1 at the benign value to 0 at the limit, per factor; the cell takes the worst.
    benign_tilt_deg: float = 10.0  # slip grows with slope beyond ~10-15 deg on sand (REFERENCE 2)
    max_tilt_deg: float = 30.0  # MER's rated static stability (about 30 deg; 31 deg seen on Mars)
    benign_roughness_m: float = 0.02  # RMS residual about the patch plane: sensor noise and gravel
    max_roughness_m: float = 0.10
    # Spread of elevations about the plane (rocks, ledges, holes): on flat ground hazcam stereo (256^2, 10 cm
    # baseline, points to 3.5 m) gives ~5 cm with the trimmed extremes.
    benign_step_m: float = 0.10
    # About one wheel diameter (25 cm) is what MER could climb and the rocks the rover must not touch; stereo reads
    # a rock's top some centimetres low (the SAD window smooths it), so the limit sits below: rocks >= 25 cm seen
    # 1-2 m ahead read >= 0.28 m (10th percentile over five fields), 10-15 cm rocks <= 0.23 m (90th).
    max_step_m: float = 0.22

    # --- arcs ---
    n_forward_arcs: int = 23  # paper
    n_backward_arcs: int = 23  # paper
    max_curvature_per_m: float = 1.0  # tightest arc: 1 m radius (sharper turns are point turns)
    point_turn_deg: float = 45.0  # heading change of each of the two point turns (left, right)
    look_ahead_m: float = 3.0  # arc length scored; the rover re-plans after step_distance_m anyway
    step_distance_m: float = 0.5  # distance driven along the winning arc per cycle (paper: 35 cm to 1 m)
    capture_distance_m: float = 1.5  # goal this close and ahead: drive the arc through it, all the way
    min_drive_m: float = 0.35  # shortest drive per cycle (paper: 35 cm)
    # The footprint the votes average over, a rectangle carried along each arc: the wheels' envelope (outer edges
    # 0.63 m to the side: track 1.1 m, wheels 0.16 m wide; 0.68 m ahead and behind) plus ~0.2 m ...
    rover_half_width_m: float = 0.8
    rover_half_length_m: float = 0.85
    # ... and the core that decides vetoes: the wheels' envelope plus ~0.1 m, less the ~0.35 m by which goodness
    # already grows a rock beyond its edge (the patch radius, less the rock's low rim that stereo reads as ground)
    core_half_width_m: float = 0.4
    core_half_length_m: float = 0.45

    # --- votes ---
    near_distance_m: float = 1.5  # unknown or impassable cells this close along an arc veto it (3 cycles' drive)
    # The ground under the rover is not in its cameras' view but it is standing on it: unknown cells this close to
    # the rover's centre count as benign.
    assume_safe_radius_m: float = 1.0
    impassable_goodness: float = 0.0  # cells at or below this goodness are impassable
    unknown_goodness: float = 0.5  # goodness of an unknown cell beyond the near part
    weight_decay_m: float = 1.5  # cell weight exp(-s / decay), s the arc length at which the footprint reaches it
    # --- waypoint vote and arbiter ---
    # path cost to the goal (see cost_to_go): per metre, 1 on benign ground, 1 + goodness_cost on the worst
    # passable, unknown_cost on unseen ground
    goodness_cost: float = 2.0
    # ... plus up to doubt_cost below doubt_goodness: stereo reads rocks low, so a cell just short of impassable may
    # hide a rock over the limit; go round such cells where there is a way
    doubt_goodness: float = 0.4
    doubt_cost: float = 3.0
    unknown_cost: float = 1.3
    # impassable cells seen from farther than certain_range_m cost far_obstacle_cost per metre instead of being walls
    certain_range_m: float = 2.5
    far_obstacle_cost: float = 6.0
    # ... plus up to clearance_cost per metre closer than clearance_range_m to a wall (falling linearly to 0 there)
    clearance_cost: float = 2.0
    clearance_range_m: float = 0.8
    # walls are grown by core_half_width_m plus this for the path: a gap only a perfectly aligned rover could thread
    # (single arcs, the core's corners swinging on a turn) is closed to the path, rather than dithered in front of
    path_margin_m: float = 0.2
    # each cycle the rover has stood within visit_radius_m of a cell adds visit_cost per metre there
    visit_cost: float = 0.5
    visit_radius_m: float = 0.3
    progress_weight: float = 1.0  # waypoint vote: distance gained towards the goal over this cycle's drive ...
    heading_weight: float = 1.0  # ... and how well the rover then faces the goal
    heading_lookahead_m: float = 1.5  # with a path-cost field: heading judged by the cost gained this far along
    use_path_cost: bool = True  # waypoint votes from the path-cost field (False: straight line to the goal)
    traversability_weight: float = 1.0  # arbiter: score = traversability_weight * trav + waypoint_weight * wp
    waypoint_weight: float = 2.0
    # ... plus worst_weight * the lowest goodness the footprint meets within near_distance_m: stereo reads a rock
    # some centimetres low, so a rock just over the limit can look merely "poor"; keep the wheels off poor cells
    worst_weight: float = 1.0
    # ... minus a preference for driving forward: a point turn makes no progress and its footprint (the ground the
    # rover stands on) always votes well; driving backward the rover does not look where it goes.
    backward_penalty: float = 0.1
    point_turn_penalty: float = 0.15
    min_traversability_vote: float = 0.2  # arcs voted below this are never chosen
    # taking back the previous move (the opposite point turn; driving back along the circle just driven, within
    # undo_curvature_per_m) costs this much: it breaks left-right-left dithering, yet a real dead end still wins
    undo_penalty: float = 0.3
    undo_curvature_per_m: float = 0.6

    def __post_init__(self) -> None:
        if self.cell_size_m <= 0 or self.map_size_m < 4 * self.cell_size_m:
            raise ValueError("cell_size_m must be > 0 and map_size_m at least 4 cells")
        if self.patch_radius_m < self.cell_size_m:
            raise ValueError(f"patch_radius_m={self.patch_radius_m}: use at least one cell ({self.cell_size_m} m)")
        for name in ("tilt_deg", "roughness_m", "step_m"):
            if not getattr(self, f"benign_{name}") < getattr(self, f"max_{name}"):
                raise ValueError(f"need benign_{name} < max_{name}")
        if self.n_forward_arcs < 1 or self.n_backward_arcs < 0:
            raise ValueError("need at least one forward arc and a non-negative number of backward arcs")
        if self.look_ahead_m + self.rover_half_width_m >= self.map_size_m / 2:
            raise ValueError("look_ahead_m + rover_half_width_m must stay inside the map window (map_size_m / 2)")

    @property
    def window_cells(self) -> int:
        """Cells per side of the evaluated window (50 for 10 m at 20 cm)."""
        return int(round(self.map_size_m / self.cell_size_m))

    @property
    def patch_cells(self) -> int:
        """Patch radius in whole cells (the margin a window needs around it for the plane fits)."""
        return int(np.ceil(self.patch_radius_m / self.cell_size_m - 1e-9))


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


# ----------------------------------------------------------------------------------------------------------------
# Arcs
# ----------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Arc:
    """A candidate steering command: a circular arc driven forward or backward, or a point turn.

    ``poses_xy_yaw`` samples the rover's path in the rover frame at the start (x forward, y left, yaw left-positive)
    up to ``look_ahead_m``; for a point turn the heading sweep at the origin.
    """

    # 1 / radius of the steering circle, centred at (0, 1 / k) in the rover frame: positive turns left driving
    # forward; driving backward on the same circle the rover backs to the left (point turn: 0)
    curvature_per_m: float
    direction: int  # +1 forward, -1 backward, 0 point turn
    turn_rad: float  # point turns: signed heading change; arcs: heading change over the look-ahead
    poses_xy_yaw: np.ndarray = field(repr=False)

    @property
    def name(self) -> str:
        if self.direction == 0:
            return f"turn_{'left' if self.turn_rad > 0 else 'right'}"
        return f"{'fwd' if self.direction > 0 else 'back'}_k{self.curvature_per_m:+.3f}"


def arc_pose(curvature_per_m: float, signed_distance_m: np.ndarray) -> np.ndarray:
    """Rover-frame poses (x, y, yaw) after driving ``signed_distance_m`` (negative = backward) on a circle."""
    s = np.asarray(signed_distance_m, dtype=float)
    k = curvature_per_m
    yaw = k * s
    if abs(k) < 1e-9:
        return np.stack([s, np.zeros_like(s), np.zeros_like(s)], axis=-1)
    return np.stack([np.sin(yaw) / k, (1.0 - np.cos(yaw)) / k, yaw], axis=-1)


def arcs(params: GestaltParams = GestaltParams()) -> list[Arc]:
    """Paper: 23 forward arcs, 23 backward arcs and 2 point turns, curvatures symmetric about straight."""
    p = params
    ds = p.cell_size_m / 2
    s = np.linspace(0.0, p.look_ahead_m, int(np.ceil(p.look_ahead_m / ds)) + 1)
    out: list[Arc] = []
    for direction, count in ((+1, p.n_forward_arcs), (-1, p.n_backward_arcs)):
        curvatures = np.linspace(-p.max_curvature_per_m, p.max_curvature_per_m, count) if count > 1 else [0.0] * count
        for k in curvatures:
            k = 0.0 if abs(k) < 1e-12 else float(k)
            out.append(Arc(k, direction, k * direction * p.look_ahead_m, arc_pose(k, direction * s)))
    for sign in (+1, -1):
        turn = sign * np.radians(p.point_turn_deg)
        yaw = np.linspace(0.0, turn, 10)
        out.append(Arc(0.0, 0, float(turn), np.stack([np.zeros(10), np.zeros(10), yaw], axis=-1)))
    return out


def goal_arc(
    pose_xy_yaw: np.ndarray, goal_xy: np.ndarray, params: GestaltParams = GestaltParams()
) -> tuple[Arc, float] | None:
    """The forward arc from the pose through the goal and its length, if the goal is within
    ``capture_distance_m``, ahead, and reachable within ``max_curvature_per_m``; else None."""
    p = params
    x, y, yaw = (float(v) for v in pose_xy_yaw)
    dx, dy = float(goal_xy[0]) - x, float(goal_xy[1]) - y
    gx = np.cos(yaw) * dx + np.sin(yaw) * dy
    gy = -np.sin(yaw) * dx + np.cos(yaw) * dy
    d2 = gx * gx + gy * gy
    if d2 > p.capture_distance_m**2 or gx <= 0.0 or d2 < 1e-6:
        return None
    k = 2.0 * gy / d2  # the circle through the origin, tangent to x, and through the goal
    if abs(k) > p.max_curvature_per_m:
        return None
    if abs(k) > 1e-9 and 2.0 * np.arctan2(abs(gy), gx) / abs(k) > p.look_ahead_m:
        return None
    length = float(np.sqrt(d2)) if abs(k) < 1e-9 else float(2.0 * np.arctan2(abs(gy), gx) / abs(k))
    k = 0.0 if abs(k) < 1e-9 else float(k)
    ds = p.cell_size_m / 2
    s = np.linspace(0.0, p.look_ahead_m, int(np.ceil(p.look_ahead_m / ds)) + 1)
    return Arc(k, 1, k * p.look_ahead_m, arc_pose(k, s)), length


def closest_approach(
    arc: Arc, pose_xy_yaw: np.ndarray, goal_xy: np.ndarray, params: GestaltParams = GestaltParams()
) -> float | None:
    """Near the goal (``capture_distance_m``): how far to drive along ``arc`` to pass closest to the goal, at
    least ``min_drive_m``, at most ``capture_distance_m`` (a driving arc only). None when the goal is farther or
    the arc is a point turn."""
    p = params
    x, y, yaw = (float(v) for v in pose_xy_yaw)
    goal = np.asarray(goal_xy, dtype=float)
    if arc.direction == 0 or np.hypot(goal[0] - x, goal[1] - y) > p.capture_distance_m:
        return None
    s = np.linspace(p.min_drive_m, p.capture_distance_m, 48)
    rel = arc_pose(arc.curvature_per_m, arc.direction * s)
    c, sn = np.cos(yaw), np.sin(yaw)
    d = np.hypot(x + c * rel[:, 0] - sn * rel[:, 1] - goal[0], y + sn * rel[:, 0] + c * rel[:, 1] - goal[1])
    return float(s[int(np.argmin(d))])


@dataclass(frozen=True)
class _Footprint:
    """Rover-frame sample points covering each arc's swept footprint, and the arc length at which each is reached.

    The rover is a rectangle (``rover_half_length_m`` x ``rover_half_width_m``) carried along the arc's poses (a
    point turn: rotated in place); samples lie on a ``cell_size_m / 2`` lattice, each with the least arc length
    at which the rectangle covers it. ``core_distance_m`` is the same for the smaller core rectangle
    (``core_half_length_m`` x ``core_half_width_m``) that decides vetoes: goodness already grows every obstacle
    (by up to the patch radius), so the core is the wheels' envelope plus a margin, less that growth.
    """

    points_xy: np.ndarray  # (n_arcs, n_samples, 2)
    distance_m: np.ndarray  # (n_arcs, n_samples); inf for padding
    core_distance_m: np.ndarray  # (n_arcs, n_samples); inf where the core never covers the sample


def _swept(poses: np.ndarray, s: np.ndarray, half_length: float, half_width: float, step: float):
    """Lattice points (rover frame at the start) covered by a rectangle carried through ``poses``, with the least
    ``s`` at which each is covered."""
    gx = np.arange(-half_length, half_length + 1e-9, step / 2)
    gy = np.arange(-half_width, half_width + 1e-9, step / 2)
    rx, ry = (a.ravel() for a in np.meshgrid(gx, gy, indexing="ij"))
    c, sn = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    wx = poses[:, 0:1] + c * rx - sn * ry
    wy = poses[:, 1:2] + sn * rx + c * ry
    key_x = np.rint(wx / step).astype(np.int64).ravel()
    key_y = np.rint(wy / step).astype(np.int64).ravel()
    dist = np.broadcast_to(s[:, None], wx.shape).ravel()
    order = np.lexsort((dist, key_y, key_x))
    kx, ky, d = key_x[order], key_y[order], dist[order]
    first = np.ones(len(kx), bool)
    first[1:] = (kx[1:] != kx[:-1]) | (ky[1:] != ky[:-1])
    return np.stack([kx[first] * step, ky[first] * step], axis=-1), d[first]


def _footprints(arc_list: list[Arc], params: GestaltParams) -> _Footprint:
    p = params
    step = p.cell_size_m / 2
    per_arc = []
    for arc in arc_list:
        poses = arc.poses_xy_yaw
        if arc.direction == 0:
            # a point turn reaches its whole footprint at once (a token 1 cm of "distance" marks the cells its
            # corners sweep beyond the rectangle it stands on)
            s = np.linspace(0.0, 0.01, len(poses))
        else:
            s = np.linspace(0.0, p.look_ahead_m, len(poses))  # poses are evenly spaced in arc length
        pts, dist = _swept(poses, s, p.rover_half_length_m, p.rover_half_width_m, step)
        core_pts, core_dist = _swept(poses, s, p.core_half_length_m, p.core_half_width_m, step)
        # core samples are lattice points of the footprint too: look their distances up by lattice key
        key = {(int(round(x / step)), int(round(y / step))): d for (x, y), d in zip(core_pts, core_dist, strict=True)}
        cd = np.array([key.get((int(round(x / step)), int(round(y / step))), np.inf) for x, y in pts])
        per_arc.append((pts, dist, cd))
    size = max(len(d) for _, d, _ in per_arc)
    points = np.zeros((len(arc_list), size, 2))
    dist = np.full((len(arc_list), size), np.inf)
    core = np.full((len(arc_list), size), np.inf)
    for a, (pts, d, c) in enumerate(per_arc):
        points[a, : len(d)], dist[a, : len(d)], core[a, : len(d)] = pts, d, c
    return _Footprint(points, dist, core)


# ----------------------------------------------------------------------------------------------------------------
# Votes and arbiter
# ----------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ArcVotes:
    """Traversability votes of all arcs (paper: "a set of traversability votes for all arcs")."""

    vote: np.ndarray  # (n_arcs,) weighted mean goodness over the swept footprint, in [0, 1]; 0 where vetoed
    vetoed: np.ndarray  # (n_arcs,) bool: an unknown or impassable cell on the near part
    cells: np.ndarray  # (n_arcs, n, n) arc length (m) at which the footprint first covers each window cell; inf
    # (n_arcs,) lowest goodness the footprint's core meets on the near part, beyond where the rover stands now
    # (unknown cells as in ``vote``); the arbiter prefers arcs whose wheels stay off doubtful ground. None: not
    # computed (counts as 1).
    worst: np.ndarray | None = None


def vote_arcs(
    window: GoodnessWindow,
    pose_xy_yaw: np.ndarray,
    arc_list: list[Arc],
    params: GestaltParams = GestaltParams(),
    footprint: _Footprint | None = None,
) -> ArcVotes:
    """Step 3: per arc, the weighted mean goodness of the cells its swept footprint covers.

    A cell's weight is ``exp(-s / weight_decay_m)`` with ``s`` the arc length at which the footprint first reaches
    it (paper: "nearby cells given higher weight"). Unknown cells count ``unknown_goodness``, except those reaching
    within ``assume_safe_radius_m`` of the rover, which it is standing on: they count as benign. An unknown or
    impassable cell on the near part (arc length up to ``near_distance_m``) of the footprint's core vetoes the arc
    (vote 0); the core is the footprint shrunk by the patch radius (see ``_Footprint``).
    """
    p = params
    fp = footprint if footprint is not None else _footprints(arc_list, p)
    x, y, yaw = (float(v) for v in pose_xy_yaw)
    c, s = np.cos(yaw), np.sin(yaw)
    world_x = x + c * fp.points_xy[..., 0] - s * fp.points_xy[..., 1]
    world_y = y + s * fp.points_xy[..., 0] + c * fp.points_xy[..., 1]
    n_arcs = len(arc_list)
    n0, n1 = window.shape
    i, j, inside = window.cell_index(np.stack([world_x.reshape(-1), world_y.reshape(-1)], axis=1))
    flat = (np.repeat(np.arange(n_arcs), fp.points_xy.shape[1]) * n0 + i.clip(0, n0 - 1)) * n1 + j.clip(0, n1 - 1)
    dist = np.where(inside, fp.distance_m.reshape(-1), np.inf)
    first = np.full(n_arcs * n0 * n1, np.inf)
    np.minimum.at(first, flat, dist)
    first_core = np.full(n_arcs * n0 * n1, np.inf)
    core_dist = np.where(inside, fp.core_distance_m.reshape(-1), np.inf)
    core = np.isfinite(core_dist)
    np.minimum.at(first_core, flat[core], core_dist[core])
    first = first.reshape(n_arcs, n0, n1)
    first_core = first_core.reshape(n_arcs, n0, n1)
    # goodness as the votes see it: unknown -> unknown_goodness, or benign under the rover
    g = window.goodness
    unknown = np.isnan(g)
    centres = window.cell_centres_xy()
    reach = p.assume_safe_radius_m + p.cell_size_m / np.sqrt(2.0)  # cell centre within radius + half a diagonal
    under_rover = np.hypot(centres[..., 0] - x, centres[..., 1] - y) <= reach
    g_vote = np.where(unknown, np.where(under_rover, 1.0, p.unknown_goodness), g)
    bad = (unknown & ~under_rover) | (g <= p.impassable_goodness)
    vetoed = ((first_core <= p.near_distance_m) & bad[None]).any(axis=(1, 2))
    covered = np.isfinite(first)
    w = np.where(covered, np.exp(-np.where(covered, first, 0.0) / p.weight_decay_m), 0.0)
    total = w.sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        vote = np.where(total > 0, (w * g_vote[None]).sum(axis=(1, 2)) / total, 0.0)
    vetoed |= total <= 0
    near = (first_core > 0.0) & (first_core <= p.near_distance_m)  # new ground only: not where it stands now
    worst = np.where(near, g_vote[None], np.inf).min(axis=(1, 2))
    worst = np.where(np.isfinite(worst), worst, 1.0)
    return ArcVotes(np.where(vetoed, 0.0, vote), vetoed, first, np.where(vetoed, 0.0, worst))


@dataclass(frozen=True)
class CostToGo:
    """Cost (metres, weighted) of the best path from each window cell to the goal; inf where blocked or cut off.

    Cells beyond the window are unknown to the map: a path leaving the window is charged its straight-line
    distance from the edge cell to the goal, so the field is a lower bound there and exact (on the grid) inside.
    """

    origin_cell: tuple[int, int]
    cell_size_m: float
    cost: np.ndarray  # (n, n)
    blocked: np.ndarray  # (n, n) bool: impassable cells grown by the footprint core

    def at(self, xy: np.ndarray) -> np.ndarray:
        """Bilinear cost at world points (N, 2) from the four surrounding cell centres; if any of them is
        infinite, the nearest cell's value. inf outside the window."""
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        n0, n1 = self.cost.shape
        u = xy[:, 0] / self.cell_size_m - 0.5 - self.origin_cell[0]
        v = xy[:, 1] / self.cell_size_m - 0.5 - self.origin_cell[1]
        i0 = np.floor(u).astype(np.int64)
        j0 = np.floor(v).astype(np.int64)
        fu, fv = u - i0, v - j0
        out = np.full(len(xy), np.inf)
        inside = (i0 >= 0) & (i0 < n0 - 1) & (j0 >= 0) & (j0 < n1 - 1)
        i, j, a, b = i0[inside], j0[inside], fu[inside], fv[inside]
        c00, c10 = self.cost[i, j], self.cost[i + 1, j]
        c01, c11 = self.cost[i, j + 1], self.cost[i + 1, j + 1]
        with np.errstate(invalid="ignore"):
            bil = (1 - a) * (1 - b) * c00 + a * (1 - b) * c10 + (1 - a) * b * c01 + a * b * c11
        near = self.cost[i + np.rint(a).astype(np.int64), j + np.rint(b).astype(np.int64)]
        out[inside] = np.where(np.isfinite(bil), bil, near)
        return out


def _disc(radius_cells: float) -> np.ndarray:
    r = int(np.floor(radius_cells + 1e-9))
    o = np.arange(-r, r + 1)
    return (o[:, None] ** 2 + o[None, :] ** 2 <= radius_cells**2 + 1e-9).astype(np.uint8)


def cost_to_go(
    window: GoodnessWindow,
    pose_xy_yaw: np.ndarray,
    goal_xy: np.ndarray,
    params: GestaltParams = GestaltParams(),
    visits: np.ndarray | None = None,
) -> CostToGo:
    """Waypoint input for the arbiter: the cost of the best grid path (8-connected, Dijkstra) to the goal.

    The goal's vote in the paper is geometric; driving "towards the goal" then runs the rover into every pocket
    between rocks and back out again. Later MER flight software (R9.2, Carsten et al. 2007) added a global
    path-cost field for exactly this: arcs are judged by how much they lower the cost still to go. A step between
    cells costs its length times ``1 + goodness_cost * (1 - goodness)``; unknown cells cost ``unknown_cost`` per
    metre (optimistic: unseen ground may be clear); impassable cells, grown by the footprint core's half-width
    plus a margin (``core_half_width_m + path_margin_m``) so that the path only uses gaps the arcs can use, are
    walls.
    Unknown cells within ``assume_safe_radius_m`` of the rover count as benign, as for the votes; other unknown
    cells the arcs could reach within ``near_distance_m`` are walls (the vetoes refuse them). ``visits`` (window
    shaped) counts the cycles the rover has stood near each cell; each adds ``visit_cost`` per metre, so a rover
    dithering between two places makes both dearer until another way wins.
    """
    p = params
    g = window.goodness
    n0, n1 = g.shape
    cs = window.cell_size_m
    x, y = float(pose_xy_yaw[0]), float(pose_xy_yaw[1])
    goal = np.asarray(goal_xy, dtype=float)
    impassable = g <= p.impassable_goodness
    # an obstacle seen only from afar may be stereo noise (elevation error grows with range squared): costly, not
    # a wall, until a nearer look confirms it
    far = impassable & (window.range_m > p.certain_range_m) if window.range_m is not None else np.zeros_like(impassable)
    wall = (impassable & ~far).astype(np.uint8)
    core = p.core_half_width_m + p.path_margin_m
    blocked = cv2.dilate(wall, _disc(core / cs)).astype(bool) if core > 0 else wall.astype(bool)
    centres = window.cell_centres_xy()
    under_rover = np.hypot(centres[..., 0] - x, centres[..., 1] - y) <= p.assume_safe_radius_m
    unknown = np.isnan(g)
    g0 = np.nan_to_num(g)
    factor = 1.0 + p.goodness_cost * (1.0 - g0) + p.doubt_cost * np.clip(1.0 - g0 / p.doubt_goodness, 0.0, 1.0)
    factor = np.where(unknown, np.where(under_rover, 1.0, p.unknown_cost), factor)
    factor = np.where(far, p.far_obstacle_cost, factor)
    if visits is not None:  # ground the rover has stood on many times: somewhere else, please
        factor = factor + p.visit_cost * visits
    # keep clear of walls where there is room: shortest paths otherwise graze them at the veto's margin
    if p.clearance_cost > 0 and wall.any():
        dist = cv2.distanceTransform((1 - wall).astype(np.uint8), cv2.DIST_L2, 5) * cs
        factor = factor + p.clearance_cost * np.clip(1.0 - dist / p.clearance_range_m, 0.0, 1.0)
    # unknown ground the arcs' vetoes would refuse (near the rover, not under it) is a wall for the path too, or the
    # field would lead into what the arcs cannot enter (a rock's shadow) and the rover would dither in front of it
    near_rover = np.hypot(centres[..., 0] - x, centres[..., 1] - y) <= p.near_distance_m + p.core_half_length_m
    blocked = blocked | (unknown & near_rover & ~under_rover)
    factor = np.where(blocked, np.inf, factor)
    idx = np.arange(n0 * n1).reshape(n0, n1)
    rows, cols, wts = [], [], []
    for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
        a = idx[max(0, -di) : n0 - max(0, di), max(0, -dj) : n1 - max(0, dj)]
        b = idx[max(0, di) : n0 + min(0, di), max(0, dj) : n1 + min(0, dj)]
        fa = factor.reshape(-1)[a.reshape(-1)]
        fb = factor.reshape(-1)[b.reshape(-1)]
        w = 0.5 * (fa + fb) * cs * np.hypot(di, dj)
        ok = np.isfinite(w)
        rows.append(a.reshape(-1)[ok])
        cols.append(b.reshape(-1)[ok])
        wts.append(w[ok])
    # a virtual source joined to the goal cell (goal inside the window) or to every open edge cell (outside)
    src = n0 * n1
    gi, gj, inside = window.cell_index(goal[None])
    inside = bool(inside[0]) and 0 < gi[0] < n0 - 1 and 0 < gj[0] < n1 - 1
    if inside:
        seeds = np.array([idx[gi[0], gj[0]]])
        seed_cost = np.array([1e-6])
    else:
        edge = np.zeros((n0, n1), bool)
        edge[[0, -1], :] = True
        edge[:, [0, -1]] = True
        edge &= ~blocked
        seeds = idx[edge]
        seed_cost = np.maximum(np.hypot(*(centres[edge] - goal).T), 1e-6)
    rows.append(np.full(len(seeds), src))
    cols.append(seeds)
    wts.append(seed_cost)
    graph = csr_matrix((np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))), shape=(src + 1, src + 1))
    dist = dijkstra(graph, directed=False, indices=src)[:src].reshape(n0, n1)
    return CostToGo(window.origin_cell, cs, dist, blocked)


def waypoint_votes(
    arc_list: list[Arc],
    pose_xy_yaw: np.ndarray,
    goal_xy: np.ndarray,
    params: GestaltParams = GestaltParams(),
    cost: CostToGo | None = None,
) -> np.ndarray:
    """Step 4a: how much each arc helps reach the goal (paper: the arbiter "takes input from waypoints"), in [0, 1].

    Judged where the rover will be after this cycle's drive (``step_distance_m`` along the arc; a point turn's full
    turn): (a) progress, the distance to the goal gained over the distance driven (-1..1; 0 for point turns), and
    (b) heading, how well the rover then faces the way on (-1..1); weighted by ``progress_weight`` and
    ``heading_weight`` and mapped to [0, 1].

    Without ``cost`` (or when it walls the rover in: no arc ends on a cell with a way to the goal) distances are
    straight lines and heading is the cosine of the angle to the goal's bearing.
    With a :class:`CostToGo` field, distance is the path cost still to go (so a detour round a rock is progress)
    and heading is the progress made by going on along the arc to ``heading_lookahead_m`` (a point turn: straight
    on after the turn; -1 into a wall).
    """
    p = params
    x, y, yaw = (float(v) for v in pose_xy_yaw)
    goal = np.asarray(goal_xy, dtype=float)
    ends = np.array(
        [
            a.poses_xy_yaw[-1] if a.direction == 0 else arc_pose(a.curvature_per_m, a.direction * p.step_distance_m)
            for a in arc_list
        ]
    )
    c, s = np.cos(yaw), np.sin(yaw)
    ex = x + c * ends[:, 0] - s * ends[:, 1]
    ey = y + s * ends[:, 0] + c * ends[:, 1]
    eyaw = yaw + ends[:, 2]
    driven = np.array([0.0 if a.direction == 0 else p.step_distance_m for a in arc_list])
    d_end = np.hypot(goal[0] - ex, goal[1] - ey)
    bearing = np.arctan2(goal[1] - ey, goal[0] - ex)
    geometric_heading = np.where(d_end > 1e-6, np.cos(bearing - eyaw), 1.0)
    c_end = cost.at(np.stack([ex, ey], axis=1)) if cost is not None else None
    if c_end is None or not np.isfinite(c_end).any():
        # no field, or one that walls the rover in (it sees no way out from here): go by the bearing, the vetoes
        # keep it safe, and the next images may open a way
        d_now = np.hypot(goal[0] - x, goal[1] - y)
        progress = np.where(driven > 0, (d_now - d_end) / np.maximum(driven, 1e-9), 0.0)
        heading = geometric_heading
    else:
        c_now = float(cost.at(np.array([[x, y]]))[0])
        if not np.isfinite(c_now):  # standing in a (falsely) blocked cell: judge against the best way out
            finite = c_end[np.isfinite(c_end)]
            c_now = float(finite.min()) + p.step_distance_m if finite.size else 0.0
        with np.errstate(invalid="ignore"):
            progress = np.where(driven > 0, (c_now - c_end) / np.maximum(driven, 1e-9), 0.0)
        progress = np.where(np.isfinite(c_end), np.clip(progress, -1.0, 1.0), -1.0)
        # heading: the progress the arc goes on making up to heading_lookahead_m (a point turn: then straight on)
        look = p.heading_lookahead_m
        far = np.array(
            [
                a.poses_xy_yaw[-1] + [look * np.cos(a.turn_rad), look * np.sin(a.turn_rad), 0.0]
                if a.direction == 0
                else arc_pose(a.curvature_per_m, a.direction * look)
                for a in arc_list
            ]
        )
        c_far = cost.at(np.stack([x + c * far[:, 0] - s * far[:, 1], y + s * far[:, 0] + c * far[:, 1]], axis=1))
        with np.errstate(invalid="ignore"):
            heading = np.clip((c_now - c_far) / look, -1.0, 1.0)
        heading = np.where(np.isfinite(c_far), heading, -1.0)
        # the goal itself is closer than the look-ahead: face it
        heading = np.where(d_end < look, geometric_heading, heading)
    mix = (p.progress_weight * progress + p.heading_weight * heading) / (p.progress_weight + p.heading_weight)
    return np.clip(0.5 * (1.0 + mix), 0.0, 1.0)


def undoes(arc_list: list[Arc], previous: Arc | None, params: GestaltParams = GestaltParams()) -> np.ndarray:
    """(n_arcs,) bool: the arcs that would take back ``previous`` - the opposite point turn, or the drive back
    along (nearly) the same circle. Dithering between a move and its undo is GESTALT's classic failure."""
    out = np.zeros(len(arc_list), bool)
    if previous is None:
        return out
    for k, a in enumerate(arc_list):
        if previous.direction == 0:
            out[k] = a.direction == 0 and np.sign(a.turn_rad) != np.sign(previous.turn_rad)
        elif a.direction == -previous.direction:
            out[k] = abs(a.curvature_per_m - previous.curvature_per_m) <= params.undo_curvature_per_m
    return out


def arbitrate(
    trav: ArcVotes,
    wp_votes: np.ndarray,
    directions: np.ndarray,
    params: GestaltParams = GestaltParams(),
    undo: np.ndarray | None = None,
) -> tuple[int | None, np.ndarray]:
    """Step 4b, the arbiter: the arc with the best weighted sum of traversability and waypoint votes.

    ``score = traversability_weight * trav + worst_weight * worst + waypoint_weight * wp - penalties``
    (``worst`` the lowest goodness the arc's core meets on its near part); penalties by ``directions`` (+1 forward,
    -1 backward, 0 point turn: ``backward_penalty``, ``point_turn_penalty``) and ``undo_penalty`` for the arcs
    marked in ``undo`` (see :func:`undoes`). Vetoed arcs and arcs voted below ``min_traversability_vote`` are out.
    Returns the winner's index (None when no arc is safe: the rover must stop) and every score (NaN where out).
    """
    p = params
    directions = np.asarray(directions)
    penalty = np.where(directions == 0, p.point_turn_penalty, np.where(directions < 0, p.backward_penalty, 0.0))
    if undo is not None:
        penalty = penalty + np.where(undo, p.undo_penalty, 0.0)
    allowed = ~trav.vetoed & (trav.vote >= p.min_traversability_vote)
    score = p.traversability_weight * trav.vote + p.waypoint_weight * np.asarray(wp_votes) - penalty
    if trav.worst is not None:
        score = score + p.worst_weight * trav.worst
    score = np.where(allowed, score, np.nan)
    if not allowed.any():
        return None, score
    return int(np.nanargmax(score)), score


# ----------------------------------------------------------------------------------------------------------------
# One GESTALT cycle
# ----------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Decision:
    """Everything one cycle decided and why, for the driver and for a logger to draw."""

    arc: Arc | None  # None: no safe arc, stop
    arc_index: int | None
    votes: ArcVotes
    waypoint_votes: np.ndarray
    scores: np.ndarray  # arbiter score per arc, NaN where vetoed or too poor
    window: GoodnessWindow
    reason: str
    cost: CostToGo | None = None  # the path-cost field the waypoint votes used (None: straight-line votes)
    # distance to drive along ``arc`` (the goal capture arc); None: the driver's usual step
    drive_m: float | None = None


class GestaltPlanner:
    """GESTALT: keeps the goodness map between cycles; :meth:`step` runs one cycle."""

    def __init__(self, params: GestaltParams = GestaltParams()) -> None:
        self.params = params
        self.map = GoodnessMap(params)
        self.arcs = arcs(params)
        self._footprint = _footprints(self.arcs, params)
        self._directions = np.array([a.direction for a in self.arcs])
        self.previous: Arc | None = None  # the arc chosen last cycle (the driver may overrule: see ``step``)
        self.visits: dict[tuple[int, int], int] = {}  # world cell -> cycles the rover stood within visit_radius_m

    def _visit(self, xy: np.ndarray) -> None:
        cs, r = self.params.cell_size_m, self.params.visit_radius_m
        ix, iy = int(np.floor(xy[0] / cs)), int(np.floor(xy[1] / cs))
        m = int(np.ceil(r / cs))
        for dx in range(-m, m + 1):
            for dy in range(-m, m + 1):
                cx, cy = (ix + dx + 0.5) * cs, (iy + dy + 0.5) * cs
                if np.hypot(cx - xy[0], cy - xy[1]) <= r + 1e-9:
                    self.visits[(ix + dx, iy + dy)] = self.visits.get((ix + dx, iy + dy), 0) + 1

    def visit_window(self, window: GoodnessWindow) -> np.ndarray:
        """The visit counts over ``window`` (window-shaped)."""
        out = np.zeros(window.shape)
        (ox, oy), (n0, n1) = window.origin_cell, window.shape
        for (ix, iy), count in self.visits.items():
            if 0 <= ix - ox < n0 and 0 <= iy - oy < n1:
                out[ix - ox, iy - oy] = count
        return out

    def step(self, points_world: np.ndarray, pose_xy_yaw: np.ndarray, goal_xy: np.ndarray) -> Decision:
        """Update map -> evaluate goodness -> vote -> arbitrate. ``points_world`` (N, 3) may be empty.

        Near the goal (within ``capture_distance_m``, in front of the rover) the arc through the goal itself is
        voted too and, if safe, driven to the goal (``Decision.drive_m``), so the rover stops on the waypoint
        rather than anywhere inside the tolerance.
        """
        p = self.params
        pose = np.asarray(pose_xy_yaw, dtype=float)
        self.map.update(points_world, pose[:2])
        window = self.map.evaluate(pose[:2])
        trav = vote_arcs(window, pose, self.arcs, p, self._footprint)
        field = cost_to_go(window, pose, goal_xy, p, self.visit_window(window)) if p.use_path_cost else None
        self._visit(pose[:2])  # counted from the next cycle on
        wp = waypoint_votes(self.arcs, pose, goal_xy, p, field)
        best, score = arbitrate(trav, wp, self._directions, p, undoes(self.arcs, self.previous, p))
        capture = goal_arc(pose, goal_xy, p)
        if capture is not None:
            arc, length = capture
            v = vote_arcs(window, pose, [arc], p)
            if not v.vetoed[0] and v.vote[0] >= p.min_traversability_vote:
                reason = f"{arc.name} to the goal ({length:.2f} m): traversability {v.vote[0]:.2f}"
                self.previous = arc
                return Decision(arc, None, trav, wp, score, window, reason, field, length)
        if best is None:
            reason = "no safe arc: every arc is vetoed or below min_traversability_vote"
            self.previous = None
            return Decision(None, None, trav, wp, score, window, reason, field)
        arc = self.arcs[best]
        self.previous = arc
        reason = f"{arc.name}: traversability {trav.vote[best]:.2f}, waypoint {wp[best]:.2f}"
        return Decision(arc, best, trav, wp, score, window, reason, field, closest_approach(arc, pose, goal_xy, p))
