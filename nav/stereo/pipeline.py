"""MER area-based stereo: band-pass, SAD window matching, consistency checks, quadratic sub-pixel, XYZ range image.

Maimone, Johnson, Cheng, Willson, Matthies (2005), section 4.1 (details in Goldberg, Maimone, Matthies 2002):
"The images are rectified and bandpass filtered before the SAD operation, a variety of stereo matching consistency
checks are applied after the SAD operation, subpixel disparities are computed by quadratic interpolation of SAD
scores, and XYZ range images are produced as the final result." MER matched 256x256 images (binned 1024x1024).

:func:`compute_disparity` runs the steps in that order, one small function each:

1. :func:`bandpass` - difference of Gaussians on each rectified image (removes brightness/gain differences between
   the cameras and the low-frequency shading; suppresses pixel noise), then :func:`quantise` to small integers.
2. :func:`row_search_window` - the disparities each row is searched over (MER's stereo also searched a limited
   range). A full-range SAD search at quarter resolution finds the disparities each row's neighbourhood contains;
   the full-resolution search covers only those, plus a margin. Hazcams look at the ground, whose disparity grows
   steadily down the image, so a row needs only a few disparities; rows where nothing matches (the sky) are skipped.
3. :func:`sad_search` - sum of absolute differences over a square window for every searched disparity along the
   epipolar line (row). One pass over the disparities gives the best match of every left pixel, the best match of
   every *right* pixel (for the left-right check), the two best scores per disparity class (for the uniqueness
   check), and keeps every SAD score so the scores around the winner can be read back for step 4.
4. :func:`subpixel_quadratic` - a parabola through the SAD scores at d-1, d, d+1.
5. Consistency checks: :func:`edge_mask` (the winner and both its neighbours were searched), :func:`texture_mask`
   (local RMS of the band-passed image), :func:`match_quality_mask` (the winning SAD is far below a chance match's),
   :func:`uniqueness_mask`, :func:`left_right_mask`, then :func:`discontinuity_mask` on the disparity image (a window
   straddling a depth edge gives up to half a window of one surface the other's disparity: pixels within half a
   window of a jump are dropped).
6. :func:`speckle_mask` - blob filter: small connected islands of disparity are removed (``cv2.filterSpeckles``).

:func:`range_image` adds the XYZ image (camera and rover frames, :mod:`nav.camera` conventions). Invalid pixels are
NaN everywhere. :func:`stereobm_baseline` is plain OpenCV StereoBM, for benchmarks.

Implementation: the SAD engine is ours rather than ``cv2.StereoBM`` because StereoBM exposes neither its SAD scores
(needed for the quadratic fit: its own sub-pixel step is an equiangular fit quantised to 1/16 px) nor the
right-referenced disparities, and cannot search a different range on each row (using it for the search would also
take a second full StereoBM run, on flipped images, for the left-right check). For each disparity, only the band of
rows that search it is processed: one ``absdiff``, one ``integral`` and two subtractions (the window sum from the
integral image), then a running max and three running minima, all inside OpenCV; the score and the disparity index
share one float32 ``key = SAD + index / 256`` so one ``min`` tracks both the best score and its argmin. Windows are
clipped at the top, bottom and right image borders (the same pixels for every disparity, so the scores stay
comparable); on the left the window must lie inside the right image. Everything after the search is a few dozen
OpenCV calls on the searched rows, written into buffers kept between calls (:class:`_Pipeline`; a fresh 256 KB
array costs page faults that take longer than the call filling it). On the 256x256 hazcam pairs of
``rover-sim bench stereo`` (32 disparities) a call takes about 2.3 ms, 1.2-1.4 times OpenCV's StereoBM on the same
machine: the coarse search and row windows about 0.45 ms, the full-resolution search 0.65 ms, the rest post-processing
(the blob filter alone 0.15-0.25 ms). Images are limited to ``H * W * 2 * cap < 2^24`` (MER binned to 256x256 for the
same reason of cost).
"""

from __future__ import annotations

import functools
import threading
from dataclasses import dataclass

import cv2
import numpy as np

from nav.camera import PinholeCamera, StereoRig

# Larger than any SAD score (window <= 21x21 px, quantised values <= 2 * 63): marks "no valid disparity".
_NO_MATCH = float(2**20)
# Disparity index stored in the fractional bits of a SAD key: key = SAD + index / _TAG (exact in float32).
_TAG = 256
_SIZE_LIMIT = 2**24  # H * W * 2 * quantise_cap must stay below (see compute_disparity)
# A parabola curvature (SAD units) this large means a neighbour's score was _NO_MATCH (not searched).
_CURVATURE_LIMIT = float(2**19)
_COARSE_SCALE = 4  # row_search_window matches the images binned 4x4 (two pyrDown)
_COARSE_MIN_VOTES = 8  # a disparity must be found this many times near a row to enter its search window


@dataclass(frozen=True)
class StereoParams:
    """Tuning of :func:`compute_disparity`; defaults for 256x256 MER navigation images (4x4-binned 1024^2)."""

    num_disparities: int = 64  # search range; navcam (fx ~309 px, 20 cm) sees ground at 1.5 m at ~41 px
    min_disparity: int = 0  # first disparity searched (px, >= 0)
    window_px: int = 9  # SAD window side (odd): 3.5 % of a 256 px image
    # Band-pass (difference of Gaussians): the fine sigma suppresses pixel noise and aliasing of the binned images;
    # the coarse one removes shading and any gain/offset difference between the two cameras.
    bandpass_sigma_fine_px: float = 0.6
    bandpass_sigma_coarse_px: float = 2.5
    # The band-passed image is scaled so that its mean absolute value maps to `quantise_mad_levels` integer levels
    # and clipped to +-`quantise_cap` (6-bit signed, like a flight fixed-point implementation; clipping also stops a
    # single bright edge dominating a window). The scale never exceeds 1/`quantise_min_mad_grey` levels per grey
    # level, so a featureless image is not amplified into noise.
    quantise_cap: int = 31
    quantise_mad_levels: float = 8.0
    quantise_min_mad_grey: float = 0.5
    # Texture: local RMS of the band-passed image (grey levels of the 8-bit input) over the window. 0.5 keeps the
    # dark, low-contrast ground in the rover's shadow (whose matches are as good as the sunlit ones).
    texture_threshold: float = 0.5
    # Uniqueness: the best SAD more than 1 px from the winner must exceed the winner's by this fraction of the
    # winner's valley depth (see uniqueness_mask). Good matches on rocky texture score >= 1.0 (99 %), a perfectly
    # periodic texture ~0.01.
    uniqueness_ratio: float = 0.5
    lr_max_diff_px: int = 1  # left-right check: |dL(u) - dR(u - dL)| <= this (integer disparities)
    # Match quality: the winning SAD must be at most this fraction of window area x local RMS texture (quantised);
    # a chance match scores about 1.1, good matches 0.2-0.4. 0 = off.
    max_sad_ratio: float = 0.8
    # Depth-edge check: a pixel is dropped when a valid pixel within half a window has a disparity more than this
    # much smaller or larger (its window reached across a depth edge). 0 = off.
    discontinuity_px: float = 1.5
    speckle_window_size: int = 40  # blobs of fewer pixels than this are removed (0 = off)
    speckle_range_px: float = 1.0  # neighbours closer than this in disparity belong to the same blob
    # Per-row search window (row_search_window): on, and the margin (px) added on both sides of the disparities
    # found at quarter resolution (sub-pixel there, so about +-1 px here). Off: every row searches the whole range.
    row_window: bool = True
    row_window_margin_px: int = 2

    def __post_init__(self) -> None:
        if self.num_disparities <= 0 or self.num_disparities % 16 or self.num_disparities > _TAG:
            raise ValueError(f"num_disparities={self.num_disparities}: use a positive multiple of 16, at most {_TAG}")
        if self.min_disparity < 0:
            raise ValueError(f"min_disparity={self.min_disparity}: must be >= 0 (rectified pair, u_right <= u_left)")
        if self.window_px < 3 or self.window_px % 2 == 0 or self.window_px > 21:
            raise ValueError(f"window_px={self.window_px}: use an odd window between 3 and 21 px")
        if not 0 < self.bandpass_sigma_fine_px < self.bandpass_sigma_coarse_px:
            raise ValueError("band-pass sigmas: need 0 < bandpass_sigma_fine_px < bandpass_sigma_coarse_px")
        if self.uniqueness_ratio < 0:
            raise ValueError(f"uniqueness_ratio={self.uniqueness_ratio}: use >= 0 (0 keeps any strictly unique match)")
        if not 1 <= self.quantise_cap <= 63:
            raise ValueError(f"quantise_cap={self.quantise_cap}: use 1..63 (values are stored in uint8)")
        if self.max_sad_ratio < 0:
            raise ValueError(f"max_sad_ratio={self.max_sad_ratio}: use >= 0 (0 = off)")
        if self.discontinuity_px < 0:
            raise ValueError(f"discontinuity_px={self.discontinuity_px}: use >= 0 (0 = off)")
        if self.row_window_margin_px < 1:
            raise ValueError(f"row_window_margin_px={self.row_window_margin_px}: use >= 1 (the winner's neighbours)")

    @property
    def half_window_px(self) -> int:
        return self.window_px // 2


@dataclass(frozen=True)
class RangeImage:
    """Output of :func:`range_image`: disparity and XYZ per left-image pixel, NaN where invalid."""

    disparity_px: np.ndarray  # (H, W) float32
    xyz_cam_m: np.ndarray  # (H, W, 3) left camera frame (x right, y down, z forward)
    xyz_rover_m: np.ndarray  # (H, W, 3) rover frame (x forward, y left, z up)
    valid: np.ndarray  # (H, W) bool

    def points_rover_m(self) -> np.ndarray:
        """The valid rover-frame points as an (N, 3) array."""
        return self.xyz_rover_m[self.valid]


@dataclass(frozen=True)
class RowWindow:
    """Disparity indices searched on each row: ``lo[v] <= index <= hi[v]`` (disparity = min_disparity + index).

    A row with ``lo > hi`` is not searched. A row may be searched at a few more disparities (bands of rows a few rows
    apart are merged); only winners strictly inside its window count.
    """

    lo: np.ndarray  # (H,) int32
    hi: np.ndarray  # (H,) int32

    @staticmethod
    def full(h_px: int, num_disparities: int) -> RowWindow:
        return RowWindow(np.zeros(h_px, np.int32), np.full(h_px, num_disparities - 1, np.int32))


@dataclass(frozen=True)
class SadSearch:
    """What one pass of :func:`sad_search` over the disparities leaves behind (all (H, W) in left pixels)."""

    index: np.ndarray  # int32 winning disparity index (disparity = min_disparity + index); -1 where none
    cost: np.ndarray  # float32 winning SAD
    cost_minus: np.ndarray  # float32 SAD at index - 1 (>= _NO_MATCH if not searched; see edge_mask)
    cost_plus: np.ndarray  # float32 SAD at index + 1 (likewise)
    second_cost: np.ndarray  # float32 best SAD more than 1 px away from the winner
    right_index: np.ndarray  # int32 winning index of each *right* pixel (column u_right); -1 where none
    window: RowWindow  # the disparity indices searched on each row


# ----------------------------------------------------------------------------------------------------------------
# Step 1: band-pass and quantisation
# ----------------------------------------------------------------------------------------------------------------


def bandpass(img: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 1 (paper: "bandpass filtered before the SAD operation"): difference of Gaussians, float32 grey levels.

    The coarse Gaussian (sigma >= 2 px) is taken at half resolution (``pyrDown``, blur, ``pyrUp``: the same width,
    a third of the work).
    """
    img = np.asarray(img)
    shape = img.shape
    return _bandpass(img, params, np.empty(shape, np.float32), np.empty(shape, np.float32))


def _bandpass(img: np.ndarray, params: StereoParams, out: np.ndarray, scratch: np.ndarray) -> np.ndarray:
    f = img if img.dtype == np.float32 else cv2.add(img, 0, dst=scratch, dtype=cv2.CV_32F)
    fine, coarse = params.bandpass_sigma_fine_px, params.bandpass_sigma_coarse_px
    h_px, w_px = f.shape
    if coarse >= 2.0 and min(h_px, w_px) >= 16:
        # the coarse Gaussian at half resolution: pyrDown and pyrUp each add a variance of 1 px^2
        sigma_half = np.sqrt(coarse**2 - 2.0) / 2.0
        half = cv2.pyrDown(f)
        cv2.GaussianBlur(half, (_gauss_ksize(sigma_half),) * 2, sigma_half, dst=half, borderType=cv2.BORDER_REFLECT)
        coarse_img = cv2.pyrUp(half, dst=_scratch(f.shape), dstsize=(w_px, h_px))
    else:
        coarse_img = cv2.GaussianBlur(
            f, (_gauss_ksize(coarse),) * 2, coarse, dst=_scratch(f.shape), borderType=cv2.BORDER_REFLECT
        )
    cv2.GaussianBlur(f, (_gauss_ksize(fine),) * 2, fine, dst=out, borderType=cv2.BORDER_REFLECT)
    return cv2.subtract(out, coarse_img, dst=out)


def _gauss_ksize(sigma_px: float) -> int:
    """Odd kernel size covering +-2.5 sigma (the tails beyond carry < 1.3 % of the weight)."""
    return 2 * int(np.ceil(2.5 * sigma_px)) + 1


def quantise(bp: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 1b: scale a band-passed image by its mean absolute value, clip, offset to uint8 ``0..2*cap``.

    Each camera is scaled by its own statistics, which cancels a gain difference between the two cameras.
    """
    return _quantise(np.asarray(bp, np.float32), params, np.empty(np.shape(bp), np.uint8))


def _quantise_gain(bp: np.ndarray, params: StereoParams) -> float:
    """Quantisation levels per grey level of a band-passed image (from its mean absolute value)."""
    mad = cv2.norm(bp, cv2.NORM_L1) / bp.size
    return params.quantise_mad_levels / max(mad, params.quantise_min_mad_grey)


def _quantise(bp: np.ndarray, params: StereoParams, out: np.ndarray, gain: float | None = None) -> np.ndarray:
    gain = _quantise_gain(bp, params) if gain is None else gain
    cap = params.quantise_cap
    q = cv2.addWeighted(bp, gain, bp, 0.0, float(cap), dst=out, dtype=cv2.CV_8U)  # rounds, saturates below 0
    return cv2.min(q, 2 * cap, dst=q)


# ----------------------------------------------------------------------------------------------------------------
# Step 2: the disparity window of each row
# ----------------------------------------------------------------------------------------------------------------


def row_search_window(bp_left: np.ndarray, bp_right: np.ndarray, params: StereoParams = StereoParams()) -> RowWindow:
    """Step 2: the disparity indices to search on each row, from a full-range search at quarter resolution.

    Both band-passed images are binned 4x4 (``cv2.pyrDown`` twice), quantised and matched over the whole range with
    the same engine (a 5 px window there, 20 px of the image). Matches that pass the left-right, uniqueness (over the
    whole range: the full-resolution search sees only the row's window) and texture checks vote for their sub-pixel
    disparity times 4. A row's window spans the disparities with at least ``_COARSE_MIN_VOTES`` votes on the coarse
    rows its SAD window touches, widened by ``row_window_margin_px`` on both sides. Rows without votes are not searched
    (the sky, featureless ground). Everything then happens on the rows from the first to the last searched one.
    """
    bp_left, bp_right = np.asarray(bp_left, np.float32), np.asarray(bp_right, np.float32)
    return _pipeline(bp_left.shape, params).row_window(bp_left, bp_right)


# ----------------------------------------------------------------------------------------------------------------
# Step 3: SAD search
# ----------------------------------------------------------------------------------------------------------------


def sad_search(
    left_q: np.ndarray, right_q: np.ndarray, params: StereoParams = StereoParams(), window: RowWindow | None = None
) -> SadSearch:
    """Step 3 (paper: "area-based algorithm using the sum of absolute differences (SAD) criterion").

    For every disparity ``s`` the window SAD between the left image and the right image shifted by ``s`` is formed
    from an integral image of ``|L(u) - R(u - s)|`` over the rows whose ``window`` contains it (all rows if
    ``window`` is None). The window is clipped at the top, bottom and right borders (the same pixels for every
    disparity) and must lie inside the right image on the left. Each score is stored as
    ``key = SAD + index / 256``. The running minimum of the keys over the left pixels gives the left winner; the
    running minimum over the *right* pixels ``u_right = u - s`` gives the right-referenced winner (the same scores,
    so exactly the disparity a search from the right image would find). Per disparity class ``index mod 3`` the
    best two keys are kept: the best score more than 1 px from the winner is then the best of three candidates (a
    class holds at most one neighbour of the winner), so the uniqueness test is exact without a second pass.
    """
    left_q, right_q = _as_pair(left_q, right_q)
    _check_size(left_q.shape, params)
    engine = _pipeline(left_q.shape, params).engine
    np.copyto(engine.left_q, left_q)
    np.copyto(engine.right_q, right_q)
    engine.search(window)
    index, right_index = engine.winners()
    cost, cost_minus, cost_plus, second = engine.scores(index)
    found = engine.found()
    return SadSearch(
        np.where(found, index, -1).astype(np.int32),
        cost.copy(),
        cost_minus.copy(),
        cost_plus.copy(),
        second.copy(),
        right_index.astype(np.int32),
        engine.window,
    )


class _Engine:
    """The SAD search over one image shape and disparity range, with its buffers (reused between calls).

    ``costs[i, v, u]`` keeps every SAD key. A disparity is written only on the rows that search it, so other rows
    may hold keys from an earlier call: they are read only for winners strictly inside their row's window. The
    columns left of each disparity's first full window are never written and read ``_NO_MATCH``.
    """

    def __init__(
        self,
        shape: tuple[int, int],
        min_disparity: int,
        num_disparities: int,
        window_px: int,
        max_value: int,
    ) -> None:
        h_px, w_px = shape
        hw = window_px // 2
        self.shape, self.min_disparity, self.num_disparities, self.window_px = (
            shape,
            min_disparity,
            num_disparities,
            window_px,
        )
        self.costs = np.full((num_disparities, h_px, w_px), _NO_MATCH, np.float32)
        self.best = np.empty((3, h_px, w_px), np.float32)  # best key per disparity class (index mod 3)
        self.second = np.empty((3, h_px, w_px), np.float32)  # second-best key per class
        self.best_right = np.empty(shape, np.float32)  # best key per right pixel
        self.tmp = np.empty(shape, np.float32)
        # |L - R| with hw zero rows above and below and hw zero columns on the right: windows there are clipped
        self.diff = np.zeros((h_px + 2 * hw, w_px + hw), np.uint8)
        # float32 integral images are exact below 2^24
        exact = (h_px + 2 * hw + 1) * (w_px + hw + 1) * max_value < 2**24
        depth = np.float32 if exact else np.int32
        self.sdepth = cv2.CV_32F if exact else cv2.CV_32S
        self.integral = np.empty((h_px + 2 * hw + 1, w_px + hw + 1), depth)
        self.band = np.empty((h_px, w_px + hw + 1), depth)
        self.window = RowWindow.full(h_px, num_disparities)
        self.u_grid, self.v_grid = _grids(shape)
        f32, u8 = (lambda: np.empty(shape, np.float32)), (lambda: np.empty(shape, np.uint8))
        self.best_all, self.cost, self.index, self.right_index = f32(), f32(), f32(), f32()
        self.rows, self.key_minus, self.key_plus, self.cost_minus, self.cost_plus = f32(), f32(), f32(), f32(), f32()
        self.far, self.far_tmp, self.best01 = f32(), f32(), f32()
        self.mask, self.mask_tmp = u8(), u8()
        self.no_match = np.full(shape, _NO_MATCH, np.float32)
        self.left_q, self.right_q = u8(), u8()  # the images to search: the caller writes them
        self.views = self._views()

    def _views(self) -> list[tuple]:
        """Per disparity: its shift, tag and the column slices of every buffer it touches (row-sliced per band)."""
        h_px, w_px = self.shape
        hw, win = self.window_px // 2, self.window_px
        views = []
        for i in range(self.num_disparities):
            s = self.min_disparity + i
            n_cols = w_px - s - hw  # left pixels u in [s + hw, w_px) have their window inside the right image
            if n_cols <= 0:
                break
            c = i % 3
            integ = self.integral[:, : w_px + hw - s + 1]
            band = self.band[:, : w_px + hw - s + 1]
            views.append(
                (
                    s,
                    i / _TAG,
                    self.left_q[:, s:],
                    self.right_q[:, : w_px - s],
                    self.diff[:, s:w_px],
                    self.diff[:, s:],
                    integ,
                    integ[win:],
                    band,
                    band[:, win:],
                    band[:, :n_cols],
                    self.costs[i, :, s + hw :],
                    self.best[c, :, s + hw :],
                    self.second[c, :, s + hw :],
                    self.tmp[:, :n_cols],
                    self.best_right[:, hw : w_px - s],
                )
            )
        return views

    def search(self, window: RowWindow | None, rows: tuple[int, int] | None = None) -> None:
        """Search ``self.left_q`` against ``self.right_q`` (quantised images, written by the caller).

        ``rows``: the running minima are reset on these rows only (all rows that search anything must be inside;
        decode only these rows).
        """
        h_px = self.shape[0]
        hw = self.window_px // 2
        self.window = window = window if window is not None else RowWindow.full(h_px, self.num_disparities)
        v0, v1 = rows if rows is not None else (0, h_px)
        self.best[:, v0:v1].fill(_NO_MATCH)
        self.second[:, v0:v1].fill(_NO_MATCH)
        self.best_right[v0:v1].fill(_NO_MATCH)
        absdiff, integral, subtract, add_weighted = cv2.absdiff, cv2.integral, cv2.subtract, cv2.addWeighted
        vmin, vmax, f32, sdepth = cv2.min, cv2.max, cv2.CV_32F, self.sdepth
        # (views stop at the first disparity with no column left in the image)
        for view, runs in zip(self.views, _row_bands(window, self.num_disparities), strict=False):
            (
                s,
                tag,
                left,
                right,
                diff_out,
                diff_in,
                integ,
                integ_hi,
                band,
                band_hi,
                band_lo,
                costs,
                best,
                second,
                tmp,
                best_right,
            ) = view
            for a, b in runs:
                r0, r1, n = max(a - hw, 0), min(b + hw, h_px), b - a
                absdiff(left[r0:r1], right[r0:r1], dst=diff_out[r0 + hw : r1 + hw])
                integral(diff_in[a : b + 2 * hw], sum=integ[: n + 2 * hw + 1], sdepth=sdepth)
                subtract(integ_hi[:n], integ[:n], dst=band[:n])  # sums over `window_px` rows
                key = costs[a:b]
                add_weighted(band_hi[:n], 1.0, band_lo[:n], -1.0, tag, dst=key, dtype=f32)  # ... and columns, tagged
                best_c, second_c = best[a:b], second[a:b]
                vmin(second_c, vmax(best_c, key, dst=tmp[:n]), dst=second_c)
                vmin(best_c, key, dst=best_c)
                right_c = best_right[a:b]
                vmin(right_c, key, dst=right_c)

    def winners(self, v0: int = 0, v1: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Winning index of every left pixel (float32; 0 where none, see found) and every right pixel (-1 if none),
        on rows ``v0:v1`` (views of workspace buffers).

        A key's index is its fractional part times 256 (exact: SAD < 2^16 and 8 fractional bits fit in float32).
        """
        rows = slice(v0, v1)
        self.rows_decoded = rows
        best01 = cv2.min(self.best[0, rows], self.best[1, rows], dst=self.best01[rows])
        best = cv2.min(best01, self.best[2, rows], dst=self.best_all[rows])
        cost = np.floor(best, out=self.cost[rows])
        index = cv2.multiply(cv2.subtract(best, cost, dst=self.index[rows]), float(_TAG), dst=self.index[rows])
        best_right = self.best_right[rows]
        right = np.floor(best_right, out=self.right_index[rows])
        right = cv2.multiply(cv2.subtract(best_right, right, dst=right), float(_TAG), dst=right)
        none = cv2.compare(best_right, _NO_MATCH, cv2.CMP_GE, dst=self.mask_tmp[rows])
        cv2.subtract(right, 1.0, dst=right, mask=none)
        return index, right

    def found(self) -> np.ndarray:
        """Where the left pixel had any candidate (bool; call after winners)."""
        return self.cost[self.rows_decoded] < _NO_MATCH

    def scores(self, index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """SAD of the winner and of index -+ 1, and the best SAD more than 1 px away (rows as in winners).

        The neighbours' keys are read back from ``costs`` (nearest-neighbour remap of its (D * H, W) view) and are
        valid only where the winner lies strictly inside its row's window (see edge_mask).
        """
        h_px, w_px = self.shape
        n = self.num_disparities
        sl = self.rows_decoded
        key_minus, key_plus, far_tmp, stack_row = self.key_minus[sl], self.key_plus[sl], self.far_tmp[sl], self.rows[sl]
        # row of (index, v) in costs as (D * H, W)
        rows = cv2.scaleAdd(index, float(h_px), self.v_grid[sl], dst=stack_row)
        if h_px * n < 32000:  # remap converts coordinates to int16
            stacked = self.costs.reshape(n * h_px, w_px)
            for key, shift in ((key_minus, -float(h_px)), (key_plus, float(h_px))):
                cv2.remap(
                    stacked,
                    self.u_grid[sl],
                    cv2.add(rows, shift, dst=far_tmp),
                    cv2.INTER_NEAREST,
                    dst=key,
                    borderMode=cv2.BORDER_CONSTANT,
                    borderValue=_NO_MATCH,
                )
        else:
            flat = rows.astype(np.int64) * w_px + np.arange(w_px)
            keys = self.costs.reshape(-1)
            np.copyto(key_minus, keys.take(flat - h_px * w_px, mode="clip"))
            np.copyto(key_plus, keys.take(flat + h_px * w_px, mode="clip"))
        cost_minus = np.floor(key_minus, out=self.cost_minus[sl])
        cost_plus = np.floor(key_plus, out=self.cost_plus[sl])
        # Best score more than 1 px from the winner. Each class holds exactly one of the disparities w - 1, w, w + 1;
        # if a class's best is that one its second is far, else its best is. Sorted, the class bests are the
        # winner's key, then mid and top: the far minimum among them is mid unless mid is a neighbour's key, else
        # top unless top is; the class seconds are always candidates.
        b0, b1, b2 = self.best[0, sl], self.best[1, sl], self.best[2, sl]
        top = cv2.max(b0, b1, dst=far_tmp)
        mid = cv2.max(self.best01[sl], cv2.min(top, b2, dst=stack_row), dst=stack_row)
        cv2.max(top, b2, dst=top)
        near, tmp_mask = self.mask[sl], self.mask_tmp[sl]
        for cand in (top, mid):
            cv2.compare(cand, key_minus, cv2.CMP_EQ, dst=near)
            cv2.bitwise_or(near, cv2.compare(cand, key_plus, cv2.CMP_EQ, dst=tmp_mask), dst=near)
            if cand is top:
                cv2.copyTo(self.no_match[sl], near, top)
            else:
                cv2.copyTo(mid, cv2.bitwise_not(near, dst=near), top)
        far = cv2.min(self.second[0, sl], self.second[1, sl], dst=self.far[sl])
        cv2.min(far, self.second[2, sl], dst=far)
        cv2.min(far, top, dst=far)
        return self.cost[sl], cost_minus, cost_plus, np.floor(far, out=far)


def _row_bands(window: RowWindow, num_disparities: int, merge_gap: int = 40) -> list[list[tuple[int, int]]]:
    """For each disparity index, the bands ``[a, b)`` of rows that search it (bands at most ``merge_gap`` rows apart
    are merged: each band costs a few OpenCV calls and half a window of rows above and below)."""
    i = np.arange(num_disparities)[:, None]
    inside = np.zeros((num_disparities, window.lo.size + 2), np.int8)
    inside[:, 1:-1] = (window.lo[None, :] <= i) & (i <= window.hi[None, :])
    change = np.diff(inside, axis=1)  # +1 where a band starts, -1 one past where it ends
    starts_i, starts_v = np.nonzero(change > 0)
    _, ends_v = np.nonzero(change < 0)
    bands: list[list[tuple[int, int]]] = [[] for _ in range(num_disparities)]
    for k, a, b in zip(starts_i.tolist(), starts_v.tolist(), ends_v.tolist(), strict=True):
        runs = bands[k]
        if runs and a - runs[-1][1] <= merge_gap:
            runs[-1] = (runs[-1][0], b)
        else:
            runs.append((a, b))
    return bands


def _grids(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """float32 column and row coordinate images (read-only views of shared arrays)."""
    h_px, w_px = shape
    grids = _GRIDS.get(w_px)
    if grids is None or grids[0].shape[0] < h_px:
        u_grid = np.tile(np.arange(w_px, dtype=np.float32), (h_px, 1))
        v_grid = np.tile(np.arange(h_px, dtype=np.float32)[:, None], (1, w_px))
        u_grid.flags.writeable = v_grid.flags.writeable = False
        grids = _GRIDS[w_px] = (u_grid, v_grid)
    return grids[0][:h_px], grids[1][:h_px]


_GRIDS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


_THREAD = threading.local()


def _scratch(shape: tuple[int, int]) -> np.ndarray:
    """A float32 scratch image of the calling thread (contents undefined; used within one function only)."""
    cache = getattr(_THREAD, "scratch", None)
    if cache is None:
        cache = _THREAD.scratch = {}
    arr = cache.get(shape)
    if arr is None:
        if len(cache) >= 4:
            cache.clear()
        arr = cache[shape] = np.empty(shape, np.float32)
    return arr


# ----------------------------------------------------------------------------------------------------------------
# Step 4: quadratic sub-pixel interpolation
# ----------------------------------------------------------------------------------------------------------------


def subpixel_quadratic(cost_minus: np.ndarray, cost: np.ndarray, cost_plus: np.ndarray) -> np.ndarray:
    """Step 4 (paper: "subpixel disparities are computed by quadratic interpolation of SAD scores").

    Vertex of the parabola through ``(-1, cost_minus), (0, cost), (1, cost_plus)``: an offset in [-0.5, 0.5] px when
    ``cost`` is the smallest of the three, NaN where the three scores are flat (no curvature).
    """
    cm = np.asarray(cost_minus, dtype=np.float64)
    cp = np.asarray(cost_plus, dtype=np.float64)
    curvature = cm + cp - 2.0 * np.asarray(cost, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = (cm - cp) / (2.0 * curvature)
    return np.where(curvature > 0, offset, np.float32(np.nan)).astype(np.float32)


def _subpixel(
    cost_minus: np.ndarray, cost: np.ndarray, cost_plus: np.ndarray, curvature: np.ndarray, offset: np.ndarray
) -> None:
    """:func:`subpixel_quadratic` for integer SAD scores in float32 (differences exact): fills ``curvature``
    (cm + cp - 2 c) and ``offset`` (meaningful where 0 < curvature < _CURVATURE_LIMIT)."""
    cv2.add(cost_minus, cost_plus, dst=curvature)
    cv2.scaleAdd(cost, -2.0, curvature, dst=curvature)
    cv2.divide(cv2.subtract(cost_minus, cost_plus, dst=offset), curvature, dst=offset, scale=0.5)


# ----------------------------------------------------------------------------------------------------------------
# Step 5: consistency checks (public: bool, True where a pixel passes; internal: uint8 255/0 into a buffer)
# ----------------------------------------------------------------------------------------------------------------


def texture_mask(bp_left: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 5a, texture: local RMS of the band-passed left image over the SAD window.

    A window without texture has a SAD curve set by noise; its minimum is meaningless (Meridiani's fine soil starved
    the hazcams, paper section 4.1). The band-passed image has no local mean, so its RMS is its standard deviation.
    """
    bp_left = np.asarray(bp_left, np.float32)
    out = np.empty(bp_left.shape, np.uint8)
    return _texture(bp_left, params.texture_threshold, params.window_px, out, np.empty(bp_left.shape, np.float32)) > 0


def _texture(bp_left: np.ndarray, threshold: float, window_px: int, out: np.ndarray, scratch: np.ndarray) -> np.ndarray:
    cv2.multiply(bp_left, bp_left, dst=scratch)
    cv2.boxFilter(scratch, -1, (window_px, window_px), dst=scratch, borderType=cv2.BORDER_REFLECT)
    return cv2.compare(scratch, threshold**2, cv2.CMP_GE, dst=out)


def match_quality_mask(search: SadSearch, bp_left: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 5f, match quality: the winning SAD must be well below that of a chance match.

    Two unrelated windows of the band-passed image differ by about 1.1 times its local RMS per pixel, so a chance
    match scores about ``1.1 * window_px^2 * RMS`` (in quantised levels); the winner must score at most
    ``max_sad_ratio`` times ``window_px^2 * RMS``. Catches a winner that is merely the best of a search range not
    containing the true disparity (a row window that missed a surface), which the other checks can pass.
    """
    bp_left = np.asarray(bp_left, np.float32)
    if params.max_sad_ratio <= 0:
        return np.ones(bp_left.shape, bool)
    mean_sq = np.empty(bp_left.shape, np.float32)
    _texture(bp_left, params.texture_threshold, params.window_px, np.empty(bp_left.shape, np.uint8), mean_sq)
    limit = _sad_limit(mean_sq, params, _quantise_gain(bp_left, params), mean_sq)
    return np.asarray(search.cost) <= limit


def _sad_limit(mean_sq: np.ndarray, params: StereoParams, gain: float, out: np.ndarray) -> np.ndarray:
    """max_sad_ratio * window area * local RMS of the band-passed image in quantised levels."""
    cv2.sqrt(mean_sq, dst=out)
    return cv2.multiply(out, params.max_sad_ratio * params.window_px**2 * gain, dst=out)


def uniqueness_mask(search: SadSearch, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 5b, uniqueness: no other valley of the SAD curve may be nearly as deep as the winner's.

    The best score more than 1 px from the winner must exceed the winner's score by ``uniqueness_ratio`` times the
    depth of the winner's valley (mean of the scores at d -+ 1 minus the score at d). Normalising by the valley depth
    rather than by the winning score keeps the test meaningful when a good match's score is mostly sensor noise.
    Rejects ambiguous matches (repetitive texture, two surfaces in one window) that a left-right check can pass.
    """
    curvature = search.cost_minus + search.cost_plus - 2 * search.cost
    out = np.empty(search.cost.shape, np.uint8)
    scratch = np.empty(search.cost.shape, np.float32)
    return _uniqueness(search.cost, search.second_cost, curvature, params.uniqueness_ratio, out, scratch) > 0


def _uniqueness(
    cost: np.ndarray, second: np.ndarray, curvature: np.ndarray, ratio: float, out: np.ndarray, scratch: np.ndarray
) -> np.ndarray:
    """second - cost > ratio * (0.5 (cost_minus + cost_plus) - cost) = ratio / 2 * curvature."""
    margin = cv2.subtract(second, cost, dst=scratch)
    cv2.scaleAdd(curvature, -0.5 * ratio, margin, dst=margin)
    return cv2.compare(margin, 0.0, cv2.CMP_GT, dst=out)


def left_right_mask(index: np.ndarray, right_index: np.ndarray, max_diff_px: int, min_disparity: int = 0) -> np.ndarray:
    """Step 5c, left-right consistency: the right pixel ``u - dL`` must match back to (about) ``u``.

    ``index`` is the integer left winner per left pixel and ``right_index`` the integer winner per right pixel (both
    disparity indices, disparity = ``min_disparity`` + index, -1 where none). A pixel passes when
    ``|dL(u) - dR(u - dL(u))| <= max_diff_px``. Occluded pixels fail: the right pixel they land on sees something
    nearer, whose own best match lies elsewhere.
    """
    index_f = np.asarray(index, np.float32)
    shape = index_f.shape
    out = np.empty(shape, np.uint8)
    ok = _left_right(
        index_f,
        np.asarray(right_index, np.float32),
        max_diff_px,
        min_disparity,
        out,
        np.empty(shape, np.float32),
        np.empty(shape, np.float32),
        np.empty(shape, np.uint8),
    )
    return (ok > 0) & (index_f >= 0)


def _left_right(
    index: np.ndarray,
    right_index: np.ndarray,
    max_diff_px: int,
    min_disparity: int,
    out: np.ndarray,
    scratch: np.ndarray,
    back: np.ndarray,
    scratch_u8: np.ndarray,
) -> np.ndarray:
    """index, right_index float32 (right -1 where none); the left index must be >= 0 (checked elsewhere)."""
    u_grid, v_grid = _grids(index.shape)
    map_u = cv2.subtract(u_grid, index, dst=scratch)
    if min_disparity:
        cv2.subtract(map_u, float(min_disparity), dst=map_u)
    cv2.remap(right_index, map_u, v_grid, cv2.INTER_NEAREST, dst=back, borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
    ok = cv2.compare(cv2.absdiff(back, index, dst=scratch), float(max_diff_px), cv2.CMP_LE, dst=out)
    return cv2.bitwise_and(ok, cv2.compare(back, 0.0, cv2.CMP_GE, dst=scratch_u8), dst=ok)


def edge_mask(search: SadSearch) -> np.ndarray:
    """Step 5d: the winner and both its neighbours were searched (inside the row's window and the image)."""
    lo, hi = search.window.lo[:, None], search.window.hi[:, None]
    return (search.index > lo) & (search.index < hi) & (search.cost_minus < _NO_MATCH) & (search.cost_plus < _NO_MATCH)


def discontinuity_mask(disparity_px: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 5e, depth edges: False within half a window of a jump of more than ``discontinuity_px``.

    A SAD window straddling a depth edge is matched by whichever surface dominates its texture, usually the nearer
    one: up to half a window of the other surface next to the edge gets that surface's disparity ("fattening").
    A valid pixel is dropped when a valid pixel within half a window (square) has a disparity more than
    ``discontinuity_px`` smaller or larger. The ground's own disparity gradient (about 0.15 px per row on a 256 px
    hazcam image) stays well below that over half a window.
    """
    d = np.asarray(disparity_px, np.float32)
    valid = np.isfinite(d)
    if params.discontinuity_px <= 0:
        return valid
    bad = (~valid).view(np.uint8) * np.uint8(255)
    fixed = cv2.multiply(cv2.patchNaNs(d.copy(), 0.0), 16.0, dtype=cv2.CV_16S)
    shape = d.shape
    ok = _discontinuity(
        fixed,
        bad,
        params.discontinuity_px,
        params.half_window_px,
        np.empty(shape, np.uint8),
        np.empty(shape, np.uint8),
        np.empty(shape, np.int16),
    )
    return valid & (ok > 0)


def _discontinuity(
    fixed: np.ndarray,
    bad: np.ndarray,
    jump_px: float,
    radius_px: int,
    out: np.ndarray,
    out2: np.ndarray,
    scratch: np.ndarray,
) -> np.ndarray:
    """``fixed``: the disparity in 1/16 px (int16); its pixels where ``bad`` (uint8 mask) are overwritten."""
    kernel = _rect_kernel(2 * radius_px + 1)
    shape, jump = fixed.shape, round(16 * jump_px)
    cv2.copyTo(_constant(shape, 32767, np.int16), bad, fixed)  # invalid pixels: never the minimum
    cv2.erode(fixed, kernel, dst=scratch)
    cv2.compare(cv2.subtract(fixed, scratch, dst=scratch), jump, cv2.CMP_LE, dst=out)
    cv2.copyTo(_constant(shape, -32768, np.int16), bad, fixed)  # ... nor the maximum
    cv2.dilate(fixed, kernel, dst=scratch)
    cv2.compare(cv2.subtract(scratch, fixed, dst=scratch), jump, cv2.CMP_LE, dst=out2)
    return cv2.bitwise_and(out, out2, dst=out)


def _constant(shape: tuple[int, int], value: float, dtype: type = np.float32) -> np.ndarray:
    """A read-only image filled with ``value`` (a view of a shared array)."""
    h_px, w_px = shape
    key = (value, np.dtype(dtype).str, w_px)
    arr = _CONSTANTS.get(key)
    if arr is None or arr.shape[0] < h_px:
        arr = _CONSTANTS[key] = np.full((h_px, w_px), value, dtype)
        arr.flags.writeable = False
    return arr[:h_px]


_CONSTANTS: dict[tuple, np.ndarray] = {}


@functools.lru_cache(maxsize=8)
def _rect_kernel(side: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_RECT, (side, side))


# ----------------------------------------------------------------------------------------------------------------
# Step 6: blob (speckle) filter
# ----------------------------------------------------------------------------------------------------------------


def speckle_mask(disparity_px: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 6, blob filter: False on connected disparity blobs smaller than ``speckle_window_size`` pixels.

    Neighbours belong to one blob when their disparities differ by at most ``speckle_range_px``
    (``cv2.filterSpeckles`` on 1/16 px fixed point; NaN pixels are treated as invalid).
    """
    d = np.asarray(disparity_px, np.float32)
    valid = np.isfinite(d)
    if params.speckle_window_size <= 0:
        return valid
    fixed = cv2.multiply(cv2.patchNaNs(d.copy(), -1.0), 16.0, dtype=cv2.CV_16S)
    return valid & (_speckle(fixed, params, np.empty(d.shape, np.uint8)) > 0)


def _speckle(fixed: np.ndarray, params: StereoParams, out: np.ndarray) -> np.ndarray:
    """``fixed``: the disparity in 1/16 px (int16), -16 where invalid; overwritten."""
    cv2.filterSpeckles(fixed, -16, params.speckle_window_size, int(round(params.speckle_range_px * 16)))
    return cv2.compare(fixed, -16, cv2.CMP_NE, dst=out)


# ----------------------------------------------------------------------------------------------------------------
# The pipeline
# ----------------------------------------------------------------------------------------------------------------


def compute_disparity(left_u8: np.ndarray, right_u8: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Left-referenced disparity (px, float32, NaN where invalid) of a rectified 8-bit pair, MER style."""
    left_u8, right_u8 = _as_pair(left_u8, right_u8)
    _check_size(left_u8.shape, params)
    return _pipeline(left_u8.shape, params).run(left_u8, right_u8)


def _check_size(shape: tuple[int, int], params: StereoParams) -> None:
    if shape[0] * shape[1] * 2 * params.quantise_cap >= _SIZE_LIMIT:
        raise ValueError(
            f"image {shape} too large for exact float32 SAD sums: bin it to 512x512 or less (MER used 256x256)"
        )


class _Pipeline:
    """:func:`compute_disparity` for one image shape and parameter set, with every buffer it needs."""

    def __init__(self, shape: tuple[int, int], params: StereoParams) -> None:
        self.shape, self.params = shape, params
        cap2 = 2 * params.quantise_cap
        self.engine = _Engine(shape, params.min_disparity, params.num_disparities, params.window_px, cap2)
        f32, u8 = (lambda s=shape: np.empty(s, np.float32)), (lambda s=shape: np.empty(s, np.uint8))
        self.bp_left, self.bp_right, self.scratch, self.scratch2, self.scratch3, self.curvature, self.offset = (
            f32() for _ in range(7)
        )
        self.ok, self.ok2, self.ok3, self.ok2x, self.ok4 = (u8() for _ in range(5))
        self.lo, self.hi = f32(), f32()
        self.fixed, self.fixed2 = np.empty(shape, np.int16), np.empty(shape, np.int16)
        self.nan = np.full(shape, np.nan, np.float32)
        self.minus16 = np.full(shape, -16, np.int16)
        # coarse search (row windows)
        f = _COARSE_SCALE
        self.coarse = None
        if params.row_window and min(shape) >= 8 * f:
            shape_c = shape
            while shape_c[0] > (shape[0] + f - 1) // f:
                shape_c = ((shape_c[0] + 1) // 2, (shape_c[1] + 1) // 2)
            self.min_c = params.min_disparity // f
            self.n_c = -(-(params.min_disparity + params.num_disparities) // f) - self.min_c + 1
            self.window_c = max(5, (params.window_px // 2) | 1)  # at 1/4 scale: 20 px or more of the image
            self.coarse = _Engine(shape_c, self.min_c, self.n_c, self.window_c, cap2)
            f32c, u8c = (lambda: np.empty(shape_c, np.float32)), (lambda: np.empty(shape_c, np.uint8))
            self.left_c, self.right_c, self.scratch_c, self.scratch_c2, self.curvature_c, self.offset_c = (
                f32c() for _ in range(6)
            )
            self.ok_c, self.ok_c2 = u8c(), u8c()
            self.bins = np.empty(shape_c, np.int32)
            n_bins = params.num_disparities + 2
            # the coarse rows a full-resolution row's SAD window touches
            v, hw = np.arange(shape[0]), params.half_window_px
            self.vote_lo = np.clip((v - hw) // f, 0, shape_c[0])
            self.vote_hi = np.clip((v + hw) // f + 1, 0, shape_c[0])
            self.row_bins = np.repeat((np.arange(shape_c[0], dtype=np.int32) * n_bins)[:, None], shape_c[1], axis=1)
            self.cum = np.zeros((shape_c[0] + 1, n_bins), np.int64)

    def row_window(self, bp_left: np.ndarray, bp_right: np.ndarray) -> RowWindow:
        params, h_px = self.params, self.shape[0]
        if self.coarse is None:
            return RowWindow.full(h_px, params.num_disparities)
        left_c, right_c = bp_left, bp_right
        while left_c.shape != self.coarse.shape:
            last = (
                left_c.shape == (self.coarse.shape[0] * 2, self.coarse.shape[1] * 2)
                or ((left_c.shape[0] + 1) // 2, (left_c.shape[1] + 1) // 2) == self.coarse.shape
            )
            left_c = cv2.pyrDown(left_c, dst=self.left_c if last else None)
            right_c = cv2.pyrDown(right_c, dst=self.right_c if last else None)
        window_c, coarse = self.window_c, self.coarse
        _quantise(left_c, params, coarse.left_q)
        _quantise(right_c, params, coarse.right_q)
        coarse.search(None)
        index, right_index = coarse.winners()
        ok = _left_right(index, right_index, 1, 0, self.ok_c, self.scratch_c, self.scratch_c2, self.ok_c2)
        # uniqueness over the whole range (the full-resolution search sees only the row's window)
        cost, cost_minus, cost_plus, second = coarse.scores(index)
        _subpixel(cost_minus, cost, cost_plus, self.curvature_c, self.offset_c)
        uniq = _uniqueness(cost, second, self.curvature_c, params.uniqueness_ratio, self.ok_c2, self.scratch_c)
        cv2.bitwise_and(ok, uniq, dst=ok)
        cv2.bitwise_and(ok, _texture(left_c, params.texture_threshold, window_c, self.ok_c2, self.scratch_c), dst=ok)
        # votes per (coarse row, full-resolution disparity index + 1): the coarse sub-pixel disparity times the
        # scale; pixels that fail vote for bin 0, which is not counted
        f, n_bins = _COARSE_SCALE, params.num_disparities + 2
        bins = cv2.addWeighted(
            index, f, self.offset_c, f, f * self.min_c - params.min_disparity + 1.0, dst=self.bins, dtype=cv2.CV_32S
        )
        cv2.min(cv2.max(bins, 1, dst=bins), n_bins - 1, dst=bins)
        cv2.add(bins, self.row_bins, dst=bins)  # the coarse row's histogram
        cv2.copyTo(self.row_bins, cv2.bitwise_not(ok, dst=ok), bins)  # its bin 0
        h_c = coarse.shape[0]
        cum = self.cum
        np.cumsum(np.bincount(bins.ravel(), minlength=h_c * n_bins).reshape(h_c, n_bins), axis=0, out=cum[1:])
        found = (cum[self.vote_hi] - cum[self.vote_lo]) >= _COARSE_MIN_VOTES  # (H, bins): disparities near each row
        found[:, 0] = False
        d_max = params.num_disparities - 1
        lo = np.argmax(found, axis=1) - (1 + params.row_window_margin_px)  # bin b holds index b - 1
        hi = (n_bins - 2 + params.row_window_margin_px) - np.argmax(found[:, ::-1], axis=1)
        np.maximum(lo, 0, out=lo)
        np.minimum(hi, d_max, out=hi)
        hi[~found.any(axis=1)] = -1  # nothing matched near this row: not searched
        return RowWindow(np.minimum(lo, d_max).astype(np.int32), hi.astype(np.int32))

    def run(self, left_u8: np.ndarray, right_u8: np.ndarray) -> np.ndarray:
        params, h_px = self.params, self.shape[0]
        bp_left = _bandpass(left_u8, params, self.bp_left, self.scratch)  # 1. band-pass
        bp_right = _bandpass(right_u8, params, self.bp_right, self.scratch)
        window = self.row_window(bp_left, bp_right)  # 2. row windows
        searched = np.nonzero(window.lo <= window.hi)[0]
        disparity = np.full(self.shape, np.nan, np.float32)  # the result: a fresh array
        if searched.size == 0:
            return disparity
        v0, v1 = int(searched[0]), int(searched[-1]) + 1  # everything below works on these rows only
        rows = slice(v0, v1)
        engine = self.engine  # 3. SAD
        gain_left = _quantise_gain(bp_left, params)
        _quantise(bp_left, params, engine.left_q, gain_left)
        _quantise(bp_right, params, engine.right_q)
        engine.search(window, (v0, v1))
        index, right_index = engine.winners(v0, v1)
        cost, cost_minus, cost_plus, second = engine.scores(index)
        curvature, offset = self.curvature[rows], self.offset[rows]
        _subpixel(cost_minus, cost, cost_plus, curvature, offset)  # 4. sub-pixel
        # 5. checks. Edge: lo < index < hi, and both neighbours' scores exist (else the curvature is huge)
        ok, tmp, tmp2, bad = self.ok[rows], self.ok2[rows], self.ok2x[rows], self.ok3[rows]
        scratch, scratch2 = self.scratch[rows], self.scratch2[rows]
        lo, hi = self.lo[rows], self.hi[rows]
        np.copyto(lo, window.lo[rows, None])
        np.copyto(hi, window.hi[rows, None])
        cv2.compare(index, lo, cv2.CMP_GT, dst=ok)
        cv2.bitwise_and(ok, cv2.compare(index, hi, cv2.CMP_LT, dst=tmp), dst=ok)
        cv2.bitwise_and(ok, cv2.compare(curvature, 0.0, cv2.CMP_GT, dst=tmp), dst=ok)
        cv2.bitwise_and(ok, cv2.compare(curvature, _CURVATURE_LIMIT, cv2.CMP_LT, dst=tmp), dst=ok)
        hw = params.half_window_px  # texture: the band-passed rows with half a window more on each side
        t0, t1 = max(v0 - hw, 0), min(v1 + hw, h_px)
        texture = _texture(
            bp_left[t0:t1], params.texture_threshold, params.window_px, self.ok4[t0:t1], self.scratch3[t0:t1]
        )
        cv2.bitwise_and(ok, texture[v0 - t0 : v1 - t0], dst=ok)
        if params.max_sad_ratio > 0:  # match quality, from the texture's local mean square
            limit = _sad_limit(self.scratch3[v0:v1], params, gain_left, scratch)
            cv2.bitwise_and(ok, cv2.compare(cost, limit, cv2.CMP_LE, dst=tmp), dst=ok)
        cv2.bitwise_and(ok, _uniqueness(cost, second, curvature, params.uniqueness_ratio, tmp, scratch), dst=ok)
        cv2.bitwise_and(
            ok, _left_right(index, right_index, params.lr_max_diff_px, 0, tmp, scratch, scratch2, tmp2), dst=ok
        )
        out = disparity[rows]
        cv2.add(index, offset, dst=out)
        if params.min_disparity:
            cv2.add(out, float(params.min_disparity), dst=out)
        cv2.bitwise_not(ok, dst=bad)
        if params.discontinuity_px > 0 or params.speckle_window_size > 0:
            fixed = cv2.multiply(out, 16.0, dst=self.fixed[rows], dtype=cv2.CV_16S)  # 1/16 px
        if params.discontinuity_px > 0:
            keep = _discontinuity(fixed, bad, params.discontinuity_px, hw, tmp, tmp2, self.fixed2[rows])
            cv2.bitwise_not(cv2.bitwise_and(ok, keep, dst=ok), dst=bad)
        if params.speckle_window_size > 0:  # 6. blob filter
            cv2.copyTo(self.minus16[rows], bad, fixed)
            keep = _speckle(fixed, params, tmp)
            cv2.bitwise_not(cv2.bitwise_and(ok, keep, dst=ok), dst=bad)
        cv2.copyTo(self.nan[rows], bad, out)
        return disparity


def _pipeline(shape: tuple[int, int], params: StereoParams) -> _Pipeline:
    """The calling thread's pipeline for this shape and parameter set (two are kept: its SAD volume is
    ``num_disparities * H * W * 4`` bytes)."""
    cache = getattr(_THREAD, "pipelines", None)
    if cache is None:
        cache = _THREAD.pipelines = {}
    key = (tuple(shape), params)
    pipe = cache.get(key)
    if pipe is None:
        if len(cache) >= 2:
            cache.pop(next(iter(cache)))
        pipe = cache[key] = _Pipeline(tuple(shape), params)
    return pipe


def _as_pair(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    left, right = np.asarray(left), np.asarray(right)
    if left.shape != right.shape or left.ndim != 2:
        raise ValueError(f"need two greyscale images of one shape, got {left.shape} and {right.shape}")
    if left.dtype != np.uint8 or right.dtype != np.uint8:
        raise ValueError("images must be uint8 (8-bit greyscale); convert with np.clip(img, 0, 255).astype(np.uint8)")
    return np.ascontiguousarray(left), np.ascontiguousarray(right)


# ----------------------------------------------------------------------------------------------------------------
# XYZ range images
# ----------------------------------------------------------------------------------------------------------------


def disparity_to_xyz_cam(disparity_px: np.ndarray, rig: StereoRig) -> np.ndarray:
    """(H, W, 3) left-camera-frame points of a disparity image; NaN where the disparity is NaN or not positive."""
    d = np.asarray(disparity_px, dtype=np.float64)
    cam = rig.left
    z = rig.depth_from_disparity(d)
    v, u = np.indices(d.shape, dtype=np.float64)
    x = (u - cam.cx_px) / cam.fx_px * z
    y = (v - cam.cy_px) / cam.fy_px * z
    return np.stack([x, y, z], axis=-1)


def xyz_cam_to_rover(xyz_cam: np.ndarray, cam: PinholeCamera) -> np.ndarray:
    """Map (..., 3) camera-frame points to the rover frame with ``cam.T_rover_cam``; NaN points stay NaN."""
    T = np.asarray(cam.T_rover_cam, dtype=np.float64)
    return np.asarray(xyz_cam, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]


def range_image(
    left_u8: np.ndarray, right_u8: np.ndarray, rig: StereoRig, params: StereoParams = StereoParams()
) -> RangeImage:
    """Disparity, camera- and rover-frame XYZ of a rectified pair (the paper's "XYZ range images")."""
    disparity = compute_disparity(left_u8, right_u8, params)
    xyz_cam = disparity_to_xyz_cam(disparity, rig)
    valid = np.isfinite(xyz_cam[..., 2])
    return RangeImage(disparity, xyz_cam, xyz_cam_to_rover(xyz_cam, rig.left), valid)


def stereobm_baseline(
    left_u8: np.ndarray, right_u8: np.ndarray, num_disparities: int = 64, window_px: int = 9
) -> np.ndarray:
    """Plain OpenCV StereoBM (default checks), float32 px with NaN where invalid: the benchmark reference."""
    left_u8, right_u8 = _as_pair(left_u8, right_u8)
    bm = cv2.StereoBM_create(numDisparities=num_disparities, blockSize=window_px)
    raw = bm.compute(left_u8, right_u8)
    disparity = raw.astype(np.float32) / 16.0
    disparity[raw < 0] = np.nan  # StereoBM marks invalid pixels with (min_disparity - 1) * 16 = -16
    return disparity
