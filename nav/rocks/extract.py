"""Rock-based cross-site localisation: rocks from dense stereo ground points, rock models, matching, adjustment.

Li, Di, Agarwal, Wang, Matthies, Howard, "Automation of ground image based Mars rover localization" (REFERENCE.md
section 5). Rocks are extracted from the dense 3D ground points of a navcam stereo panorama taken at a rover *site*
(a stop), modelled by analytic surfaces, matched between two sites and used as tie points in an incremental
adjustment of the rover positions.

0. Dense points: :func:`panorama_points` turns one large navcam pair into rover-frame points at two scales (the
   near field binned, the far field at full resolution), through :func:`disparity_tiled` (MER SAD stereo,
   :mod:`nav.stereo`, in strips of rows, since one call is limited to about 512 x 512 pixels),
   :func:`refine_disparity` (Lucas-Kanade sub-pixel refinement) and :func:`drop_depth_edges` (no mixed-depth
   points along rock outlines).

:func:`extract_rocks` then reads as the paper's steps in order:

1. :func:`extract_peaks` - rock peaks: local height maxima in a window (50 x 50 cm), with a height range in the
   window above a threshold (10 cm) and enough points in it.
2. :func:`fit_local_plane` - a robust plane through the ground points around the peak; the rock height is the
   peak's distance to it, and the points above it are the rock candidates.
3. :func:`grow_rock_region` - region growing from the peak: radius 0.3 h, grown by the largest nearest-neighbour
   spacing per step, stopped at 1.7 h or when nothing is added.
4. :func:`fit_rock_model` / :func:`fit_best_model` - least-squares fits of a hemispheroid, a semi-ellipsoid, a cone
   and a tetrahedron with iterative removal of far points; the model with the lowest
   information criterion (RMS penalised by its number of parameters) is kept.

Then, between sites:

5. :func:`match_rocks` - candidate pairs by model parameters (height, size, volume, surface area), then the
   geometric pattern of the rock positions (a RANSAC over pairs of candidates for a 4-DOF transform: yaw and
   translation, since roll and pitch come from the accelerometers), then a weighted least-squares transform from the
   consistent matches and a significance test against chance agreement.
6. :class:`SiteChain` - incremental adjustment of a chain of sites (the paper: matched rocks are tie points of an
   incremental bundle adjustment), as a weighted least-squares pose graph: unknown site poses (x, y, z, yaw) and
   systematic tie-point error terms, observed as odometry legs between consecutive sites (VO's own covariance, the
   gyro's heading drift) and as site-to-site transforms from the matched rocks (covariance from the fit, scaled by
   the match residuals), solved every time a site is added.

Frames: each site's points and rocks are in that site's *estimated* world frame (x east, y north, z up), i.e. rover
frame points mapped through the onboard pose estimate at the site; the estimates of two sites differ from the truth
and from each other by the odometry drift, which is what matching and adjustment recover. A :class:`Pose4` maps
points of one frame into another. Pure numpy/scipy/OpenCV: nothing here reads ground truth or any simulator state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from nav.camera import StereoRig
from nav.stereo import StereoParams, compute_disparity, disparity_to_xyz_cam, xyz_cam_to_rover

RockShape = Literal["hemispheroid", "semi_ellipsoid", "cone", "tetrahedron"]
ROCK_SHAPES: tuple[RockShape, ...] = ("hemispheroid", "semi_ellipsoid", "cone", "tetrahedron")

# Tetrahedron footprint in normalised coordinates (u / (L/2), v / (W/2)), centroid at the origin, apex above it:
# its extent along the rock's x is L and along y is W (the convention of the terrain generator's rock models).
_TETRA_BASE_N = np.array([[4.0 / 3.0, 0.0], [-2.0 / 3.0, 1.0], [-2.0 / 3.0, -1.0]])
_SAD_LIMIT = 2**24  # compute_disparity sums SAD in float32: strip rows * width * 2 * quantise_cap must stay below
_MAX_STACKED_ROWS = 32766  # ... and its per-disparity cost planes, stacked, stay below OpenCV's 32767 rows


# ================================================================================================================
# Parameters and data types
# ================================================================================================================


@dataclass(frozen=True)
class RockParams:
    """Tuning of rock extraction and modelling (paper values where it gives them)."""

    # 1. peaks
    grid_cell_m: float = 0.10  # peaks are searched on a grid of this cell (each cell's robust top point)
    peak_window_m: float = 0.5  # paper: local maxima within a 50 x 50 cm window
    min_height_range_m: float = 0.10  # paper: height range within the window above 10 cm
    min_window_points: int = 12  # paper: "at least a set of ground points within the window"
    top_rank: int = 2  # a cell's top is its k-th highest point (one stray stereo point makes no peak)
    # 2. local plane
    plane_radius_m: float = 1.0  # ground points within max(this, plane_radius_h * h) of the peak
    plane_radius_h: float = 2.5
    plane_iterations: int = 6  # one-sided robust refits (rock points are positive outliers)
    plane_clip_sigma: float = 2.0
    min_rock_height_m: float = 0.12  # detection threshold on the peak's height above the plane
    min_height_sigma: float = 4.0  # ... and at least this many ground-noise sigmas
    # 3. region growing
    grow_start_h: float = 0.3  # paper: from 0.3 h ...
    grow_stop_h: float = 1.7  # ... to 1.7 h
    candidate_clearance_m: float = 0.02  # rock candidates stand at least this (and 1.5 ground sigma) above the plane
    min_step_m: float = 0.05  # a growth step (the largest nearest-neighbour spacing) is clipped to this range
    max_step_m: float = 0.15  # (a floor bridges stereo dropouts; a ceiling keeps neighbours apart)
    min_region_points: int = 25
    # 4. models
    fit_iterations: int = 5  # fits alternated with removal of far points
    outlier_sigma: float = 2.5  # points farther than this many RMS from the surface are dropped ...
    outlier_floor_m: float = 0.02  # ... but never closer than this
    # model selection (a departure from the paper's plain lowest RMS, see fit_best_model): BIC over the fit residuals
    # with this many stereo points counted as one independent residual. Neighbouring points share the correlation
    # window, the sub-pixel refinement and the rendered mesh's facets, so their errors are far from independent;
    # a sweep of 1-128 on a cached survey of the rock_localization sites (the bench's own survey, so the bench's
    # type figure is not out of sample) put the best values at 16-64 (1 = plain BIC, which lets the richer models
    # win by fitting correlated stereo error).
    selection_points_per_sample: float = 32.0
    # well-observed rocks (the ones whose model type the data can tell apart, see observation_quality)
    well_observed_min_points: int = 200  # ~ 6 parameters x selection_points_per_sample
    well_observed_min_coverage_deg: float = 180.0  # azimuth span of the rock's points about its apex
    well_observed_max_noise_frac: float = 0.15  # stereo range sigma at the rock / the rock's height
    max_points_per_fit: int = 600  # regions are thinned to this many points before fitting (speed)
    noise_weighted_fit: bool = False  # weigh model-fit residuals by the points' stereo noise (needs the cameras)
    fit_sigma_floor_m: float = 0.01  # point noise of noise-weighted fits: floor, k r^2 along the line of sight ...
    angular_sigma_rad: float = 5e-4  # ... and this times the range across it
    # stereo range noise, sigma = k r^2 with k = sigma_disparity / (f B): 2048 px navcam, 0.12 px -> 2.4e-4 / m
    range_sigma_per_m2: float = 2.4e-4
    # duplicates and tie points
    duplicate_radius_m: float = 0.3  # a peak this close to an extracted rock (plus its half length) is that rock
    tie_point: Literal["apex", "top_median"] = "apex"  # see ExtractedRock.position_m
    tie_top_fraction: float = 0.75  # top_median: the median of the points above this fraction of the top


@dataclass(frozen=True)
class RockPeak:
    """Step 1 output: the robust top point of a grid cell that is the highest in its window."""

    xyz_m: np.ndarray  # (3,)
    height_range_m: float  # window's top minus its bottom
    n_window_points: int


@dataclass(frozen=True)
class LocalPlane:
    """Step 2 output: ``n . p = d`` with ``n`` the unit upward normal; ``sigma_m`` is the ground points' noise."""

    normal: np.ndarray  # (3,)
    offset_m: float
    sigma_m: float
    n_points: int

    def height_of(self, points: np.ndarray) -> np.ndarray:
        """Signed distance of (N, 3) points above the plane."""
        return np.asarray(points, dtype=float) @ self.normal - self.offset_m

    def basis(self) -> np.ndarray:
        """3x3 rotation whose columns are the plane frame's axes (x along world x projected, z the normal)."""
        n = self.normal
        ex = np.array([1.0, 0.0, 0.0]) - n[0] * n
        if np.linalg.norm(ex) < 1e-6:
            ex = np.array([0.0, 1.0, 0.0]) - n[1] * n
        ex /= np.linalg.norm(ex)
        return np.column_stack([ex, np.cross(n, ex), n])


@dataclass(frozen=True)
class RockModel:
    """A fitted analytic rock: in its local plane frame, centred at ``centre_xyz_m`` (the base centre, on the plane).

    ``length_m``/``width_m`` are the footprint's full extents along the rock's own x/y (x at ``yaw_rad`` from the
    plane frame's x, which is world x projected on the plane), ``height_m`` the height above the plane at the
    centre; the generator's conventions (``terrains.Rock``), so parameters compare directly. ``rms_m`` is the RMS
    distance of the inlier points to the surface.
    """

    shape: RockShape
    centre_xyz_m: np.ndarray  # (3,) base centre (tetrahedron: footprint centroid, under the apex)
    length_m: float
    width_m: float
    height_m: float
    yaw_rad: float
    rms_m: float
    n_points: int
    n_inliers: int
    plane_normal: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    @property
    def top_xyz_m(self) -> np.ndarray:
        """The apex (all four models have their top above the base centre)."""
        return self.centre_xyz_m + self.height_m * self.plane_normal

    @property
    def footprint_area_m2(self) -> float:
        if self.shape == "tetrahedron":
            return 0.5 * self.length_m * self.width_m
        return 0.25 * math.pi * self.length_m * self.width_m

    @property
    def equivalent_diameter_m(self) -> float:
        return math.sqrt(4.0 * self.footprint_area_m2 / math.pi)

    @property
    def volume_m3(self) -> float:
        if self.shape in ("hemispheroid", "semi_ellipsoid"):
            return 2.0 / 3.0 * self.footprint_area_m2 * self.height_m
        return self.footprint_area_m2 * self.height_m / 3.0

    @property
    def surface_area_m2(self) -> float:
        """Area of the curved (or faceted) surface above the base, by numerical integration."""
        return _surface_area(self.shape, 0.5 * self.length_m, 0.5 * self.width_m, self.height_m)

    def descriptor(self) -> np.ndarray:
        """Model parameters compared between sites: height, equivalent diameter, cube roots of volume and area."""
        return np.array(
            [self.height_m, self.equivalent_diameter_m, self.volume_m3 ** (1 / 3), math.sqrt(self.surface_area_m2)]
        )


@dataclass(frozen=True)
class ExtractedRock:
    """One rock of a site: its peak, local plane, surface points and best model (plus every model tried)."""

    peak: RockPeak
    plane: LocalPlane
    height_m: float  # step 2: the peak's distance to the plane
    points: np.ndarray  # (K, 3) step 3: the rock's surface points
    model: RockModel  # step 4: the selected model (fit_best_model)
    models: dict[str, RockModel] = field(default_factory=dict)
    tie_xyz_m: np.ndarray | None = None  # see position_m

    @property
    def position_m(self) -> np.ndarray:
        """Tie-point position: the top of the rock, the part of a convex rock every site sees.

        ``RockParams.tie_point``: ``"apex"`` (default), the best model's apex, or ``"top_median"``, the median of
        the points above ``tie_top_fraction`` of the rock's height (no model, but pulled toward the cameras by the
        foreshortened far side of the top). A few centimetres of bias along the line of sight remain either way;
        :class:`SiteChain` can calibrate a constant part of it.
        """
        return self.model.top_xyz_m if self.tie_xyz_m is None else self.tie_xyz_m


# ================================================================================================================
# Dense points
# ================================================================================================================


def disparity_tiled(left_u8: np.ndarray, right_u8: np.ndarray, params: StereoParams, margin_px: int = 16) -> np.ndarray:
    """Disparity (px, NaN where invalid) of a rectified pair of any size, matched in horizontal strips.

    :func:`nav.stereo.compute_disparity` is limited to about 512 x 512 pixels (exact float32 SAD sums); rows are
    epipolar lines, so a large image is matched as strips of rows, each padded by ``margin_px`` rows (at least the
    SAD half window plus the band-pass kernel) that are discarded. Strip statistics (band-pass scaling) are local.
    """
    h_px, w_px = left_u8.shape
    max_rows = min((_SAD_LIMIT - 1) // (w_px * 2 * params.quantise_cap), _MAX_STACKED_ROWS // params.num_disparities)
    core = max_rows - 2 * margin_px
    if core < 32:
        raise ValueError(f"images {w_px} px wide are too wide to match in strips; bin them first")
    disparity = np.full((h_px, w_px), np.nan, np.float32)
    for r0 in range(0, h_px, core):
        r1 = min(h_px, r0 + core)
        a, b = max(0, r0 - margin_px), min(h_px, r1 + margin_px)
        strip = compute_disparity(left_u8[a:b], right_u8[a:b], params)
        disparity[r0:r1] = strip[r0 - a : r1 - a]
    return disparity


def refine_disparity(
    left_u8: np.ndarray, right_u8: np.ndarray, disparity_px: np.ndarray, window_px: int = 11, iterations: int = 4
) -> np.ndarray:
    """Sub-pixel refinement of a SAD disparity by 1-D Lucas-Kanade along the rows (NaN stays NaN).

    The parabola through three SAD scores is biased toward whole pixels ("pixel locking"); here each pixel's
    disparity is corrected by the least-squares shift that best aligns the right image, warped by the current
    disparities (bicubic), with the left image over a ``window_px`` window: ``delta = -sum(e g) / sum(g^2)``, ``e``
    the brightness difference and ``g`` the warped right image's row gradient. The field is smoothed (normalised
    Gaussian, sigma 1.5 px, valid pixels only) between iterations, which removes the window sums' null space.
    Pixels that move by more than 1 px are dropped. About 3x smaller errors on textured ground near the rover.
    """
    left = cv2.GaussianBlur(left_u8.astype(np.float32), (0, 0), 0.8)
    right = cv2.GaussianBlur(right_u8.astype(np.float32), (0, 0), 0.8)
    grad = cv2.Sobel(right, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    h_px, w_px = left.shape
    xs, ys = np.meshgrid(np.arange(w_px, dtype=np.float32), np.arange(h_px, dtype=np.float32))
    valid = np.isfinite(disparity_px)
    weight = valid.astype(np.float32)
    norm = np.maximum(cv2.GaussianBlur(weight, (0, 0), 1.5), 1e-3)
    d0 = np.where(valid, disparity_px, 0.0).astype(np.float32)
    d = d0.copy()
    win = (window_px, window_px)
    for _ in range(iterations):
        mx = xs - d
        warped = cv2.remap(right, mx, ys, cv2.INTER_CUBIC)
        g = cv2.remap(grad, mx, ys, cv2.INTER_CUBIC)
        e = left - warped
        num = cv2.boxFilter(e * g, -1, win, normalize=False)
        den = cv2.boxFilter(g * g, -1, win, normalize=False)
        step = np.clip(-num / np.maximum(den, 1e-3), -0.5, 0.5)
        d = cv2.GaussianBlur((d + step) * weight, (0, 0), 1.5) / norm
    return np.where(valid & (np.abs(d - d0) < 1.0), d, np.nan).astype(np.float32)


def drop_depth_edges(disparity_px: np.ndarray, jump: float, radius_px: int, occlusion_px: int = 0) -> np.ndarray:
    """NaN out pixels within ``radius_px`` of a disparity jump larger than ``jump`` times the local disparity, and
    pixels up to ``occlusion_px`` to the left of a nearer surface.

    A SAD window straddling a rock's outline mixes the rock with the ground behind it, so the outline pixels get
    depths in between: streaks of false points behind every rock, at rock height. Smooth ground changes its
    disparity by a few per cent over a few rows; an occluding outline by far more. Left of a near object (in the
    left image) lies ground the right camera cannot see; its windows match the object instead ("fattening"), which
    widens every rock on one side: that band is cut ``occlusion_px`` wide.
    """
    d = np.asarray(disparity_px, dtype=np.float32)
    valid = np.isfinite(d)
    kernel = np.ones((2 * radius_px + 1, 2 * radius_px + 1), np.uint8)
    hi = cv2.dilate(np.where(valid, d, -np.inf).astype(np.float32), kernel)
    lo = cv2.erode(np.where(valid, d, np.inf).astype(np.float32), kernel)
    with np.errstate(invalid="ignore", over="ignore"):
        edge = (hi - lo) > jump * np.where(valid, d, 0.0)
        if occlusion_px > 0:  # the largest disparity within occlusion_px to the right of each pixel
            right = np.ones((1, 2 * occlusion_px + 1), np.uint8)
            right[0, :occlusion_px] = 0
            hi_right = cv2.dilate(np.where(valid, d, -np.inf).astype(np.float32), right)
            edge |= (hi_right - d) > jump * np.where(valid, d, 0.0)
    return np.where(valid & ~edge, d, np.nan).astype(np.float32)


@dataclass(frozen=True)
class PanoramaStereoParams:
    """Two-scale dense stereo of large navcam images: the near field binned, the far field at full resolution.

    Near the rover the binned image has all the range resolution needed and a quarter of the pixels; the far
    field (disparities below ``far_max_disparity_px`` at full resolution, ~5 m for a 2048 px navcam) keeps the full
    resolution, which halves the range error of rocks 20-30 m away.
    """

    binning: int = 2
    near: StereoParams = StereoParams(num_disparities=128, window_px=11, speckle_window_size=100)
    far: StereoParams = StereoParams(num_disparities=128, window_px=15, speckle_window_size=200)
    far_max_disparity_px: float = 100.0
    edge_jump: float = 0.08  # pixels within edge_radius_px of a disparity jump above this fraction are dropped
    edge_radius_px: int = 2  # (full-resolution pixels; halved for the binned image)
    occlusion_px: int = 0  # band cut left of near surfaces (full-resolution pixels; halved for the binned image)
    refine_near: bool = True  # Lucas-Kanade refinement of the binned (near-field) disparities
    refine_window_px: int = 11


def panorama_points(
    left_u8: np.ndarray, right_u8: np.ndarray, rig: StereoRig, params: PanoramaStereoParams = PanoramaStereoParams()
) -> np.ndarray:
    """(N, 3) rover-frame points of one rectified navcam pair, two scales (see :class:`PanoramaStereoParams`).

    1. Bin the pair and match it (strips, Lucas-Kanade refinement). 2. The far band is every row above the lowest
    row whose median binned disparity is still below ``far_max_disparity_px`` (full-resolution pixels); match it
    at full resolution. 3. Drop the pixels at depth discontinuities (:func:`drop_depth_edges`). 4. Far-band rows
    come from the full-resolution disparities, the rest from the binned ones.
    """
    k = params.binning
    h_px, w_px = left_u8.shape
    small_l = cv2.resize(left_u8, (w_px // k, h_px // k), interpolation=cv2.INTER_AREA)
    small_r = cv2.resize(right_u8, (w_px // k, h_px // k), interpolation=cv2.INTER_AREA)
    rig_small = rig.scaled(1.0 / k)
    d_small = disparity_tiled(small_l, small_r, params.near)
    if params.refine_near:
        d_small = refine_disparity(small_l, small_r, d_small, params.refine_window_px)
    d_small = drop_depth_edges(d_small, params.edge_jump, max(1, params.edge_radius_px // k), params.occlusion_px // k)
    rows_valid = np.isfinite(d_small).any(axis=1)
    row_med = np.full(len(d_small), np.nan)
    row_med[rows_valid] = np.nanmedian(d_small[rows_valid], axis=1) * k
    far_rows = np.flatnonzero(np.nan_to_num(row_med, nan=np.inf) < params.far_max_disparity_px)
    split_small = int(far_rows.max()) + 1 if len(far_rows) else 0  # binned rows [0, split) are far
    points = []
    if split_small > 0:
        split = split_small * k
        d_full = disparity_tiled(left_u8[: split + 16], right_u8[: split + 16], params.far)[:split]
        d_full = drop_depth_edges(d_full, params.edge_jump, params.edge_radius_px, params.occlusion_px)
        full = np.full((h_px, w_px), np.nan, np.float32)
        full[:split] = d_full
        xyz = xyz_cam_to_rover(disparity_to_xyz_cam(full, rig), rig.left)
        points.append(xyz[:split][np.isfinite(xyz[:split, :, 2])])
    xyz_s = xyz_cam_to_rover(disparity_to_xyz_cam(d_small, rig_small), rig_small.left)
    near = xyz_s[split_small:]
    points.append(near[np.isfinite(near[..., 2])])
    return np.concatenate(points).reshape(-1, 3)


def voxel_downsample(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """One point per occupied voxel (the mean of its points): thins the dense near field, keeps the sparse far."""
    p = np.asarray(points, dtype=float)
    if len(p) == 0:
        return p.reshape(0, 3)
    ijk = np.floor((p - p.min(axis=0)) / voxel_m).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse, p)
    return sums / counts[:, None]


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


def _surface_area(shape: RockShape, a: float, b: float, h: float, n: int = 48) -> float:
    """Area of a model's surface above its base: a polar grid over the footprint, lifted, summed as triangles."""
    if shape == "tetrahedron":
        base = _TETRA_BASE_N * np.array([a, b])
        apex = np.array([0.0, 0.0, h])
        total = 0.0
        for i in range(3):
            p0 = np.r_[base[i], 0.0]
            p1 = np.r_[base[(i + 1) % 3], 0.0]
            total += 0.5 * float(np.linalg.norm(np.cross(p0 - apex, p1 - apex)))
        return total
    rs = np.linspace(0.0, 1.0, n // 2 + 1)
    th = np.linspace(0.0, 2.0 * math.pi, n + 1)
    R, T = np.meshgrid(rs, th, indexing="ij")
    frac = np.sqrt(np.maximum(1.0 - R * R, 0.0)) if shape != "cone" else 1.0 - R
    X, Y, Z = a * R * np.cos(T), b * R * np.sin(T), h * frac
    P = np.stack([X, Y, Z], axis=-1)
    p00, p01, p10, p11 = P[:-1, :-1], P[:-1, 1:], P[1:, :-1], P[1:, 1:]
    t1 = 0.5 * np.linalg.norm(np.cross(p10 - p00, p11 - p00), axis=-1)
    t2 = 0.5 * np.linalg.norm(np.cross(p11 - p00, p01 - p00), axis=-1)
    return float(t1.sum() + t2.sum())


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
        return Pose4(self.R @ other.t_m + self.t_m, _wrap(self.yaw_rad + other.yaw_rad))

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


def _wrap(a: float) -> float:
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
        if abs(_wrap(T.yaw_rad - prior.yaw_rad)) > params.max_yaw_rad:
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
    return SiteMatch(pairs, T, _pose4_covariance(pb[pairs[:, 1]], T, cov), float(np.sqrt(np.mean(res**2))), n_cand)


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


def _pose4_covariance(b: np.ndarray, T: Pose4, cov: np.ndarray) -> np.ndarray:
    """(4, 4) covariance of a weighted least-squares :class:`Pose4` (inverse Gauss-Newton Hessian)."""
    W = np.linalg.inv(cov)
    y = T.yaw_rad
    dR = np.array([[-math.sin(y), -math.cos(y), 0.0], [math.cos(y), -math.sin(y), 0.0], [0.0, 0.0, 0.0]])
    J = np.zeros((len(b), 3, 4))
    J[:, :, :3] = np.eye(3)
    J[:, :, 3] = b @ dR.T
    H = np.einsum("nki,nkl,nlj->ij", J, W, J)
    return np.linalg.inv(H + 1e-12 * np.eye(4))


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
                self._edges.append(self._rock_edge(j, k, m))
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

    def _rock_edge(self, i: int, j: int, m: SiteMatch) -> _Edge:
        """The relative pose the rock match gives, its covariance (scaled by the match residuals' variance factor)
        and its derivative with respect to the tie-point error terms (by refitting with shifted tie points)."""
        P = self.params
        a, b = self.sites[i], self.sites[j]
        pa = a.rocks.positions[m.pairs[:, 0]]
        pb = b.rocks.positions[m.pairs[:, 1]]
        ca = tie_point_covariances(pa, a.rocks.sensor_xyz_m, P.match)
        cb = tie_point_covariances(pb, b.rocks.sensor_xyz_m, P.match)
        cov_pairs = ca + np.einsum("ij,njk,lk->nil", m.transform.R, cb, m.transform.R)
        res = pa - m.transform.apply(pb)
        chi2 = float(np.einsum("ni,nij,nj->", res, np.linalg.inv(cov_pairs), res))
        variance_factor = chi2 / max(3 * len(res) - 4, 1)

        def relative(t: np.ndarray) -> np.ndarray:
            z = a.estimate.inverse().compose(Pose4.from_vector(t)).compose(b.estimate).as_vector()
            z[3] = _wrap(z[3])
            return z

        t0 = m.transform.as_vector()
        z = relative(t0)
        J = _numeric_jacobian(relative, t0, 1e-6)
        cov = J @ (m.covariance * variance_factor) @ J.T
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
                x0=m.transform,
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
        """Weighted least squares over the site poses (site 0 fixed) and the tie-point error terms.

        Each edge's residual is the measured relative pose (a rock edge corrected by its derivative times the error
        terms) minus the one the current poses give, whitened by the edge's covariance; the error terms carry a
        prior of ``range_bias_prior_m``.
        """
        n = len(self.sites)
        if n < 2:
            return
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
                r[3] = _wrap(r[3])
                out.append(W @ r)
            out.append(bias / P.range_bias_prior_m)
            return np.concatenate(out)

        x0 = np.concatenate([s.adjusted.as_vector() for s in self.sites[1:]] + [np.zeros(n_bias)])
        res = least_squares(residuals, x0, method="trf", x_scale="jac", max_nfev=200)
        X = poses(res.x)
        for k in range(1, n):
            self.sites[k].correction = X[k].compose(self.sites[k].estimate.inverse())
        self.range_bias_m = tuple(float(b) for b in res.x[4 * (n - 1) :])


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
