"""Steps 5-6 of the MER stereo pipeline (Maimone et al. 2005, section 4.1): "a variety of stereo matching
consistency checks are applied after the SAD operation" - match quality, uniqueness, left-right, edge and
depth-discontinuity checks - and the blob (speckle) filter. The texture check (5a) is in
:mod:`nav.stereo.bandpass`.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from nav.stereo.bandpass import quantise_gain, texture_into
from nav.stereo.params import NO_MATCH, SadSearch, StereoParams
from nav.stereo.sad import grids

# ----------------------------------------------------------------------------------------------------------------
# Step 5: consistency checks (public: bool, True where a pixel passes; internal: uint8 255/0 into a buffer)
# ----------------------------------------------------------------------------------------------------------------


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
    texture_into(bp_left, params.texture_threshold, params.window_px, np.empty(bp_left.shape, np.uint8), mean_sq)
    limit = sad_limit(mean_sq, params, quantise_gain(bp_left, params), mean_sq)
    return np.asarray(search.cost) <= limit


def sad_limit(mean_sq: np.ndarray, params: StereoParams, gain: float, out: np.ndarray) -> np.ndarray:
    """max_sad_ratio * window area * local RMS of the band-passed image in quantised levels."""
    cv2.sqrt(mean_sq, dst=out)
    return cv2.addWeighted(out, params.max_sad_ratio * params.window_px**2 * gain, out, 0.0, 0.0, dst=out)


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
    return uniqueness(search.cost, search.second_cost, curvature, params.uniqueness_ratio, out, scratch) > 0


def uniqueness(
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
    ok = left_right(
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


def left_right(
    index: np.ndarray,
    right_index: np.ndarray,
    max_diff_px: int,
    min_disparity: int,
    out: np.ndarray,
    scratch: np.ndarray,
    back: np.ndarray,
    scratch_u8: np.ndarray,
    none_index: float = -1.0,
) -> np.ndarray:
    """index, right_index float32 (right ``none_index`` where none); the left index must be >= 0 (checked
    elsewhere). With ``none_index < -max_diff_px`` a right pixel without a winner (or outside the image) fails the
    difference test by itself, and the separate ``back >= 0`` test is skipped (the same mask, two calls fewer)."""
    u_grid, v_grid = grids(index.shape)
    map_u = cv2.subtract(u_grid, index, scratch)
    if min_disparity:
        cv2.subtract(map_u, float(min_disparity), map_u)
    cv2.remap(right_index, map_u, v_grid, cv2.INTER_NEAREST, back, cv2.BORDER_CONSTANT, none_index)
    ok = cv2.compare(cv2.absdiff(back, index, scratch), float(max_diff_px), cv2.CMP_LE, out)
    if none_index < -max_diff_px:
        return ok
    return cv2.bitwise_and(ok, cv2.compare(back, 0.0, cv2.CMP_GE, scratch_u8), ok)


def edge_mask(search: SadSearch) -> np.ndarray:
    """Step 5d: the winner and both its neighbours were searched (inside the row's window and the image)."""
    lo, hi = search.window.lo[:, None], search.window.hi[:, None]
    return (search.index > lo) & (search.index < hi) & (search.cost_minus < NO_MATCH) & (search.cost_plus < NO_MATCH)


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
    ok = discontinuity(
        fixed,
        bad,
        params.discontinuity_px,
        params.half_window_px,
        np.empty(shape, np.uint8),
        np.empty(shape, np.uint8),
        np.empty(shape, np.int16),
    )
    return valid & (ok > 0)


def discontinuity(
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
    return valid & (speckle(fixed, params, np.empty(d.shape, np.uint8)) > 0)


def speckle(fixed: np.ndarray, params: StereoParams, out: np.ndarray) -> np.ndarray:
    """``fixed``: the disparity in 1/16 px (int16), -16 where invalid; overwritten."""
    speckle_filter(fixed, params)
    return cv2.compare(fixed, -16, cv2.CMP_NE, dst=out)


def speckle_filter(fixed: np.ndarray, params: StereoParams) -> None:
    """:func:`speckle` in place: the pixels of removed blobs become -16."""
    cv2.filterSpeckles(fixed, -16, params.speckle_window_size, int(round(params.speckle_range_px * 16)))
