"""MER area-based stereo: band-pass, SAD window matching, consistency checks, quadratic sub-pixel, XYZ range image.

Maimone, Johnson, Cheng, Willson, Matthies (2005), section 4.1 (details in Goldberg, Maimone, Matthies 2002):
"The images are rectified and bandpass filtered before the SAD operation, a variety of stereo matching consistency
checks are applied after the SAD operation, subpixel disparities are computed by quadratic interpolation of SAD
scores, and XYZ range images are produced as the final result." MER matched 256x256 images (binned 1024x1024).

:func:`compute_disparity` runs the steps in that order, one small function each:

1. :func:`bandpass` - difference of Gaussians on each rectified image (removes brightness/gain differences between
   the cameras and the low-frequency shading; suppresses pixel noise), then :func:`quantise` to small integers.
2. :func:`sad_search` - sum of absolute differences over a square window for every disparity along the epipolar
   line (row). One pass over the disparities gives the best match of every left pixel, the best match of every
   *right* pixel (for the left-right check), the two best scores per disparity class (for the uniqueness check), and
   keeps every SAD score so the scores around the winner can be read back for step 3.
3. :func:`subpixel_quadratic` - a parabola through the SAD scores at d-1, d, d+1.
4. Consistency checks, each a boolean mask: :func:`texture_mask` (local variance of the band-passed image),
   :func:`uniqueness_mask`, :func:`left_right_mask`, and the winner must not sit at the end of the search range.
5. :func:`speckle_mask` - blob filter: small connected islands of disparity are removed (``cv2.filterSpeckles``).

:func:`range_image` adds the XYZ image (camera and rover frames, :mod:`nav.camera` conventions). Invalid pixels are
NaN everywhere. :func:`stereobm_baseline` is plain OpenCV StereoBM, for benchmarks.

Implementation: the SAD engine is ours rather than ``cv2.StereoBM`` because StereoBM exposes neither its SAD scores
(needed for the quadratic fit: its own sub-pixel step is an equiangular fit quantised to 1/16 px) nor the
right-referenced disparities. Each disparity costs one ``absdiff`` + ``integral`` + two subtractions (the window sum
from the integral image) and four running minima, all on 256x256 arrays inside OpenCV; the score and the disparity
index share one float32 ``key = SAD + index / 256`` so a single ``min`` tracks both the best score and its argmin.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import cv2
import numpy as np

from nav.camera import PinholeCamera, StereoRig

# Larger than any SAD score (window <= 21x21 px, quantised values <= 2 * 63): marks "no valid disparity".
_NO_MATCH = float(2**20)
# Disparity index stored in the fractional bits of a SAD key: key = SAD + index / _TAG (exact in float32).
_TAG = 256


@dataclass(frozen=True)
class StereoParams:
    """Tuning of :func:`compute_disparity`; defaults for 256x256 MER navigation images (4x4-binned 1024^2)."""

    num_disparities: int = 64  # search range; navcam (fx ~309 px, 20 cm) sees ground at 1.5 m at ~41 px
    min_disparity: int = 0  # first disparity searched (px, >= 0)
    window_px: int = 9  # SAD window side (odd); ~3.5 % of the 256 px image, as in JPL's 7x7..11x11 practice
    # Band-pass (difference of Gaussians): the fine sigma suppresses pixel noise and aliasing of the binned images;
    # the coarse one removes shading and any gain/offset difference between the two cameras.
    bandpass_sigma_fine_px: float = 0.7
    bandpass_sigma_coarse_px: float = 3.0
    # The band-passed image is scaled so that its mean absolute value maps to `quantise_mad_levels` integer levels
    # and clipped to +-`quantise_cap` (6-bit signed, like a flight fixed-point implementation; clipping also stops a
    # single bright edge dominating a window). The scale never exceeds 1/`quantise_min_mad_grey` levels per grey
    # level, so a featureless image is not amplified into noise.
    quantise_cap: int = 31
    quantise_mad_levels: float = 8.0
    quantise_min_mad_grey: float = 0.5
    # Texture: local standard deviation of the band-passed image (grey levels of the 8-bit input) over the window.
    texture_threshold: float = 1.0
    # Uniqueness: the best SAD more than 1 px from the winner must exceed the winner's by this fraction of the
    # winner's valley depth (see uniqueness_mask). Good matches on rocky texture score >= 1.0 (99 %), a perfectly
    # periodic texture ~0.01.
    uniqueness_ratio: float = 0.5
    lr_max_diff_px: int = 1  # left-right check: |dL(u) - dR(u - dL)| <= this (integer disparities)
    speckle_window_size: int = 40  # blobs of fewer pixels than this are removed (0 = off)
    speckle_range_px: float = 1.0  # neighbours closer than this in disparity belong to the same blob

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
class SadSearch:
    """What one pass of :func:`sad_search` over the disparities leaves behind (all (H, W) in left pixels)."""

    index: np.ndarray  # int32 winning disparity index (disparity = min_disparity + index); -1 where none
    cost: np.ndarray  # float32 winning SAD
    cost_minus: np.ndarray  # float32 SAD at index - 1 (>= _NO_MATCH if not searched)
    cost_plus: np.ndarray  # float32 SAD at index + 1 (>= _NO_MATCH if not searched)
    second_cost: np.ndarray  # float32 best SAD more than 1 px away from the winner
    right_index: np.ndarray  # int32 winning index of each *right* pixel (column u_right); -1 where none


# ----------------------------------------------------------------------------------------------------------------
# Step 1: band-pass and quantisation
# ----------------------------------------------------------------------------------------------------------------


def bandpass(img: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 1 (paper: "bandpass filtered before the SAD operation"): difference of Gaussians, float32 grey levels."""
    f = np.asarray(img, dtype=np.float32)
    fine, coarse = params.bandpass_sigma_fine_px, params.bandpass_sigma_coarse_px
    fine_img = cv2.GaussianBlur(f, (_gauss_ksize(fine),) * 2, fine, borderType=cv2.BORDER_REFLECT)
    coarse_img = cv2.GaussianBlur(f, (_gauss_ksize(coarse),) * 2, coarse, borderType=cv2.BORDER_REFLECT)
    return cv2.subtract(fine_img, coarse_img)


def _gauss_ksize(sigma_px: float) -> int:
    """Odd kernel size covering +-2.5 sigma (the tails beyond carry < 1.3 % of the weight)."""
    return 2 * int(np.ceil(2.5 * sigma_px)) + 1


def quantise(bp: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 1b: scale a band-passed image by its mean absolute value, clip, offset to uint8 ``0..2*cap``.

    Each camera is scaled by its own statistics, which cancels a gain difference between the two cameras.
    """
    mad = cv2.norm(bp, cv2.NORM_L1) / bp.size
    gain = params.quantise_mad_levels / max(mad, params.quantise_min_mad_grey)
    cap = params.quantise_cap
    q = cv2.addWeighted(bp, gain, bp, 0.0, float(cap), dtype=cv2.CV_8U)  # rounds, saturates below 0
    return cv2.min(q, 2 * cap, dst=q)


# ----------------------------------------------------------------------------------------------------------------
# Step 2: SAD search over all disparities
# ----------------------------------------------------------------------------------------------------------------


class _Workspace:
    """Buffers and per-disparity array views reused between calls of one image shape and parameter set.

    Fresh multi-megabyte buffers cost page faults, and building ~15 numpy views per disparity costs Python time;
    both are paid once here. Each disparity's views address the same regions on every call, so the parts of
    ``costs`` a disparity cannot reach keep ``_NO_MATCH`` forever.
    """

    def __init__(self, shape: tuple[int, int], params: StereoParams) -> None:
        h_px, w_px = shape
        hw, win = params.half_window_px, params.window_px
        self.shape, self.params = shape, params
        self.left = np.zeros(shape, np.uint8)
        self.right = np.zeros(shape, np.uint8)
        self.costs = np.full((params.num_disparities, h_px, w_px), _NO_MATCH, np.float32)  # every SAD key
        self.best = np.empty((3, h_px, w_px), np.float32)  # best key per disparity class (index mod 3)
        self.second = np.empty((3, h_px, w_px), np.float32)  # second-best key per class
        self.best_right = np.empty(shape, np.float32)  # best key per right pixel
        self.pixel_flat = np.arange(h_px * w_px, dtype=np.intp).reshape(shape)
        absdiff = np.empty(shape, np.uint8)
        integral = np.empty((h_px + 1, w_px + 1), np.float32)
        rowsum = np.empty((h_px + 1 - win, w_px + 1), np.float32)
        tmp = np.empty(shape, np.float32)
        rows = slice(hw, h_px - hw)
        self.steps: list[tuple] = []
        for i in range(params.num_disparities):
            s = params.min_disparity + i
            n_cols = w_px - s - 2 * hw  # left pixels u in [s + hw, w_px - hw) have a full window in both images
            if n_cols <= 0:
                break
            integ = integral[:, : w_px - s + 1]
            band = rowsum[:, : w_px - s + 1]
            cols = slice(s + hw, w_px - hw)
            c = i % 3
            self.steps.append(
                (
                    self.left[:, s:],
                    self.right[:, : w_px - s],
                    absdiff[:, : w_px - s],
                    integ,
                    integ[win:],
                    integ[:-win],
                    band,
                    band[:, win:],
                    band[:, :-win],
                    i / _TAG,
                    self.costs[i, rows, cols],
                    self.best[c, rows, cols],
                    self.second[c, rows, cols],
                    tmp[: h_px - 2 * hw, :n_cols],
                    self.best_right[rows, hw : w_px - hw - s],
                )
            )


_WORKSPACES = threading.local()


def _workspace(shape: tuple[int, int], params: StereoParams) -> _Workspace:
    """The calling thread's workspace for this shape and parameter set (rebuilt when either changes)."""
    ws = getattr(_WORKSPACES, "ws", None)
    if ws is None or ws.shape != shape or ws.params != params:
        ws = _Workspace(shape, params)
        _WORKSPACES.ws = ws
    return ws


def _key_index(key: np.ndarray) -> np.ndarray:
    """Disparity index stored in the fractional bits of SAD keys (int32)."""
    return (key * _TAG).astype(np.int32) & (_TAG - 1)


def sad_search(left_q: np.ndarray, right_q: np.ndarray, params: StereoParams = StereoParams()) -> SadSearch:
    """Step 2 (paper: "area-based algorithm using the sum of absolute differences (SAD) criterion").

    For every disparity ``s`` the window SAD between the left image and the right image shifted by ``s`` is formed
    from an integral image of ``|L(u) - R(u - s)|``; a window must lie fully inside both images. Each score is
    stored as ``key = SAD + index / 256``. The running minimum of the keys over the left pixels gives the left
    winner; the running minimum over the *right* pixels ``u_right = u - s`` gives the right-referenced winner (the
    same scores, so exactly the disparity a search from the right image would find). Per disparity class
    ``index mod 3`` the best two keys are kept: the best score more than 1 px from the winner is then the best of
    three candidates (a class holds at most one neighbour of the winner), so the uniqueness test is exact without a
    second pass over the scores.
    """
    ws = _workspace(left_q.shape, params)
    np.copyto(ws.left, left_q)
    np.copyto(ws.right, right_q)
    ws.best.fill(_NO_MATCH)
    ws.second.fill(_NO_MATCH)
    ws.best_right.fill(_NO_MATCH)
    absdiff, integral, subtract, add_weighted = cv2.absdiff, cv2.integral, cv2.subtract, cv2.addWeighted
    vmin, vmax, f32 = cv2.min, cv2.max, cv2.CV_32F
    for lq, rq, diff, integ, integ_hi, integ_lo, band, band_hi, band_lo, tag, key, best, second, tmp, right in ws.steps:
        absdiff(lq, rq, dst=diff)
        integral(diff, sum=integ, sdepth=f32)
        subtract(integ_hi, integ_lo, dst=band)  # sums over `window_px` rows
        add_weighted(band_hi, 1.0, band_lo, -1.0, tag, dst=key)  # ... and columns: the window SAD, tagged
        vmin(second, vmax(best, key, dst=tmp), dst=second)
        vmin(best, key, dst=best)
        vmin(right, key, dst=right)
    return _decode_search(ws, params)


def _decode_search(ws: _Workspace, params: StereoParams) -> SadSearch:
    """Winner, its neighbours' scores, the best score more than 1 px away and the right winners, from the keys."""
    best = cv2.min(cv2.min(ws.best[0], ws.best[1]), ws.best[2])
    fixed = (best * _TAG).astype(np.int32)
    index = fixed & (_TAG - 1)
    cost = (fixed >> 8).astype(np.float32)
    # scores at index -+ 1, read back from the stored keys; unsearched disparities read _NO_MATCH
    plane = ws.pixel_flat.size
    keys = ws.costs.reshape(-1)
    flat = ws.pixel_flat + index * plane
    cost_minus = np.floor(keys.take(flat - plane, mode="clip"))
    cost_plus = np.floor(keys.take(flat + plane, mode="clip"))
    cost_minus[index == 0] = _NO_MATCH
    cost_plus[index == params.num_disparities - 1] = _NO_MATCH
    # best score more than 1 px from the winner: per class, its best key unless that is the winner or a neighbour
    near = np.abs(_key_index(ws.best) - index) <= 1
    second = np.floor(np.where(near, ws.second, ws.best).min(axis=0))
    index[best >= _NO_MATCH] = -1
    right_index = _key_index(ws.best_right)
    right_index[ws.best_right >= _NO_MATCH] = -1
    return SadSearch(index, cost, cost_minus, cost_plus, second, right_index)


# ----------------------------------------------------------------------------------------------------------------
# Step 3: quadratic sub-pixel interpolation
# ----------------------------------------------------------------------------------------------------------------


def subpixel_quadratic(cost_minus: np.ndarray, cost: np.ndarray, cost_plus: np.ndarray) -> np.ndarray:
    """Step 3 (paper: "subpixel disparities are computed by quadratic interpolation of SAD scores").

    Vertex of the parabola through ``(-1, cost_minus), (0, cost), (1, cost_plus)``: an offset in [-0.5, 0.5] px when
    ``cost`` is the smallest of the three, NaN where the three scores are flat (no curvature).
    """
    cm = np.asarray(cost_minus, dtype=np.float32)
    cp = np.asarray(cost_plus, dtype=np.float32)
    curvature = cm + cp - 2.0 * np.asarray(cost, dtype=np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = (cm - cp) / (2.0 * curvature)
    return np.where(curvature > 0, offset, np.float32(np.nan)).astype(np.float32)


# ----------------------------------------------------------------------------------------------------------------
# Step 4: consistency checks (each returns True where a pixel passes)
# ----------------------------------------------------------------------------------------------------------------


def texture_mask(bp_left: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 4a, texture: local standard deviation of the band-passed left image over the SAD window.

    A window without texture has a SAD curve set by noise; its minimum is meaningless (Meridiani's fine soil starved
    the hazcams, paper section 4.1).
    """
    k = (params.window_px, params.window_px)
    mean = cv2.boxFilter(bp_left, -1, k, borderType=cv2.BORDER_REFLECT)
    mean_sq = cv2.sqrBoxFilter(bp_left, -1, k, borderType=cv2.BORDER_REFLECT)
    var = mean_sq - mean * mean
    return var >= params.texture_threshold**2


def uniqueness_mask(search: SadSearch, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 4b, uniqueness: no other valley of the SAD curve may be nearly as deep as the winner's.

    The best score more than 1 px from the winner must exceed the winner's score by ``uniqueness_ratio`` times the
    depth of the winner's valley (mean of the scores at d -+ 1 minus the score at d). Normalising by the valley depth
    rather than by the winning score keeps the test meaningful when a good match's score is mostly sensor noise.
    Rejects ambiguous matches (repetitive texture, two surfaces in one window) that a left-right check can pass.
    """
    depth = 0.5 * (search.cost_minus + search.cost_plus) - search.cost
    return search.second_cost - search.cost > params.uniqueness_ratio * depth


def left_right_mask(index: np.ndarray, right_index: np.ndarray, max_diff_px: int, min_disparity: int = 0) -> np.ndarray:
    """Step 4c, left-right consistency: the right pixel ``u - dL`` must match back to (about) ``u``.

    ``index`` is the integer left winner per left pixel and ``right_index`` the integer winner per right pixel (both
    disparity indices, disparity = ``min_disparity`` + index, -1 where none). A pixel passes when
    ``|dL(u) - dR(u - dL(u))| <= max_diff_px``. Occluded pixels fail: the right pixel they land on sees something
    nearer, whose own best match lies elsewhere.
    """
    w_px = index.shape[1]
    shift = index + min_disparity
    ok = (index >= 0) & (np.arange(w_px, dtype=np.int32)[None, :] >= shift)
    flat = np.arange(index.size, dtype=np.intp).reshape(index.shape) - shift
    back = right_index.reshape(-1).take(flat, mode="clip")
    return ok & (back >= 0) & (np.abs(back - index) <= max_diff_px)


def edge_mask(search: SadSearch) -> np.ndarray:
    """Step 4d: the winner must have both neighbours searched (not at the end of the disparity range or window)."""
    return (search.index >= 0) & (search.cost_minus < _NO_MATCH) & (search.cost_plus < _NO_MATCH)


# ----------------------------------------------------------------------------------------------------------------
# Step 5: blob (speckle) filter
# ----------------------------------------------------------------------------------------------------------------


def speckle_mask(disparity_px: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 5, blob filter: False on connected disparity blobs smaller than ``speckle_window_size`` pixels.

    Neighbours belong to one blob when their disparities differ by at most ``speckle_range_px``
    (``cv2.filterSpeckles`` on 1/16 px fixed point; NaN pixels are treated as invalid).
    """
    valid = np.isfinite(disparity_px)
    if params.speckle_window_size <= 0:
        return valid
    fixed = np.where(valid, np.rint(disparity_px * 16.0), -16.0).astype(np.int16)
    cv2.filterSpeckles(fixed, -16, params.speckle_window_size, int(round(params.speckle_range_px * 16)))
    return valid & (fixed != -16)


# ----------------------------------------------------------------------------------------------------------------
# The pipeline
# ----------------------------------------------------------------------------------------------------------------


def compute_disparity(left_u8: np.ndarray, right_u8: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Left-referenced disparity (px, float32, NaN where invalid) of a rectified 8-bit pair, MER style."""
    left_u8, right_u8 = _as_pair(left_u8, right_u8)
    bp_left, bp_right = bandpass(left_u8, params), bandpass(right_u8, params)  # 1. band-pass
    search = sad_search(quantise(bp_left, params), quantise(bp_right, params), params)  # 2. SAD
    offset = subpixel_quadratic(search.cost_minus, search.cost, search.cost_plus)  # 3. sub-pixel
    ok = edge_mask(search)  # 4. checks
    ok &= texture_mask(bp_left, params)
    ok &= uniqueness_mask(search, params)
    ok &= left_right_mask(search.index, search.right_index, params.lr_max_diff_px, params.min_disparity)
    disparity = np.where(ok, (search.index + params.min_disparity) + offset, np.float32(np.nan)).astype(np.float32)
    disparity[~speckle_mask(disparity, params)] = np.nan  # 5. blob filter
    return disparity


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
