"""Step 1 of the MER stereo pipeline (Maimone et al. 2005, section 4.1): the rectified images are "bandpass
filtered before the SAD operation" (difference of Gaussians) and quantised to small integers; plus the
texture check (step 5a), the local RMS of the band-passed image.
"""

from __future__ import annotations

import functools
import threading

import cv2
import numpy as np

from nav.stereo.params import StereoParams

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
    return bandpass_into(img, params, np.empty(shape, np.float32), np.empty(shape, np.float32))


def bandpass_into(img: np.ndarray, params: StereoParams, out: np.ndarray, scratch: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint8:  # (numpy converts uint8 to float32 in half the time of cv2.add)
        np.copyto(scratch, img)
        f = scratch
    else:
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
    return quantise_into(np.asarray(bp, np.float32), params, np.empty(np.shape(bp), np.uint8))


def quantise_gain(bp: np.ndarray, params: StereoParams) -> float:
    """Quantisation levels per grey level of a band-passed image (from its mean absolute value)."""
    mad = cv2.norm(bp, cv2.NORM_L1) / bp.size
    return params.quantise_mad_levels / max(mad, params.quantise_min_mad_grey)


def quantise_into(bp: np.ndarray, params: StereoParams, out: np.ndarray, gain: float | None = None) -> np.ndarray:
    gain = quantise_gain(bp, params) if gain is None else gain
    cap = params.quantise_cap
    q = cv2.addWeighted(bp, gain, bp, 0.0, float(cap), dst=out, dtype=cv2.CV_8U)  # rounds, saturates below 0
    return cv2.min(q, 2 * cap, dst=q)


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
# Step 5a: texture (local RMS of the band-passed image; see nav.stereo.checks for the other checks)
# ----------------------------------------------------------------------------------------------------------------


def texture_mask(bp_left: np.ndarray, params: StereoParams = StereoParams()) -> np.ndarray:
    """Step 5a, texture: local RMS of the band-passed left image over the SAD window.

    A window without texture has a SAD curve set by noise; its minimum is meaningless (Meridiani's fine soil starved
    the hazcams, paper section 4.1). The band-passed image has no local mean, so its RMS is its standard deviation.
    """
    bp_left = np.asarray(bp_left, np.float32)
    out = np.empty(bp_left.shape, np.uint8)
    return (
        texture_into(bp_left, params.texture_threshold, params.window_px, out, np.empty(bp_left.shape, np.float32)) > 0
    )


def texture_into(
    bp_left: np.ndarray, threshold: float, window_px: int, out: np.ndarray, scratch: np.ndarray
) -> np.ndarray:
    """Local mean square of ``bp_left`` over the window into ``scratch`` (float32 sums: OpenCV's float box filter
    sums in float64, a third slower at 256^2), thresholded into ``out``."""
    cv2.multiply(bp_left, bp_left, dst=scratch)
    kernel = _mean_kernel(window_px)
    cv2.sepFilter2D(scratch, -1, kernel, kernel, dst=scratch, borderType=cv2.BORDER_REFLECT)
    return cv2.compare(scratch, threshold**2, cv2.CMP_GE, dst=out)


@functools.lru_cache(maxsize=8)
def _mean_kernel(window_px: int) -> np.ndarray:
    return np.full((window_px, 1), 1.0 / window_px, np.float32)
