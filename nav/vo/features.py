"""Image side of the MER visual odometry: corner detection and correlation matching.

Cheng, Maimone, Matthies (2005), section 2, "Feature Detection" (step 1) and "Feature-based Stereo Matching"
(step 2); the same correlation search serves "Feature Tracking" (step 5, see :func:`nav.vo.track_features`).

Images are greyscale arrays (uint8 or float); pixels ``(u, v)`` = (column, row), centre of the top-left pixel
at (0, 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from nav.vo.params import VoParams


# ------------------------------------------------------------------------------------------------------------
# Step 1: feature detection
# ------------------------------------------------------------------------------------------------------------
def harris_response(img: np.ndarray, params: VoParams) -> np.ndarray:
    """Harris corner response ``det(M) - k trace(M)^2`` of the image (float32, same shape)."""
    return cv2.cornerHarris(_as_f32(img), blockSize=params.harris_block_px, ksize=3, k=params.harris_k)


def detect_features(img: np.ndarray, params: VoParams, mask: np.ndarray | None = None) -> np.ndarray:
    """Step 1: corners spread over the image, strongest first: (N, 2) integer pixel positions (u, v).

    A grid of cells smaller than the minimum spacing (``min_spacing_px / 2``) is laid on the Harris response;
    the strongest corner of each cell is a candidate; candidates are taken strongest first while they keep
    ``min_spacing_px`` from every feature already taken, up to ``max_features``. ``mask`` (bool, image shape)
    marks pixels allowed to hold a feature (e.g. to exclude the rover's own hardware or predicted shadow).
    """
    resp = harris_response(img, params)
    h_img, w_img = resp.shape
    b = max(params.border_px, params.window_px // 2 + 2)
    if mask is not None:
        resp = np.where(mask, resp, -np.inf).astype(np.float32)
    cell = max(1, int(params.min_spacing_px // 2))
    ny, nx = (h_img - 2 * b) // cell, (w_img - 2 * b) // cell
    if ny <= 0 or nx <= 0:
        return np.zeros((0, 2))
    sub = resp[b : b + ny * cell, b : b + nx * cell].reshape(ny, cell, nx, cell).transpose(0, 2, 1, 3)
    sub = sub.reshape(ny, nx, cell * cell)
    k = np.argmax(sub, axis=2)
    best = np.take_along_axis(sub, k[..., None], axis=2)[..., 0]
    gy, gx = np.mgrid[0:ny, 0:nx]
    v = b + gy * cell + k // cell
    u = b + gx * cell + k % cell
    peak = float(np.max(best)) if np.isfinite(best).any() else 0.0
    keep = np.isfinite(best) & (best > 0) & (best > params.harris_rel_threshold * peak)
    order = np.argsort(-best[keep], kind="stable")
    cand_u, cand_v = u[keep][order], v[keep][order]

    # greedy minimum-distance selection, strongest first; a painted disc marks the exclusion zone of each pick
    blocked = np.zeros((h_img, w_img), np.uint8)
    radius = int(np.ceil(params.min_spacing_px)) - 1
    chosen: list[tuple[int, int]] = []
    for cu, cv in zip(cand_u.tolist(), cand_v.tolist(), strict=True):
        if blocked[cv, cu]:
            continue
        chosen.append((cu, cv))
        if len(chosen) >= params.max_features:
            break
        cv2.circle(blocked, (cu, cv), radius, 1, thickness=-1)
    return np.asarray(chosen, dtype=float).reshape(-1, 2)


# ------------------------------------------------------------------------------------------------------------
# Step 2: pseudo-normalised correlation with biquadratic sub-pixel peak
# ------------------------------------------------------------------------------------------------------------
def pseudo_normalized_correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Paper's score ``2 sum(a b) / (sum(a^2) + sum(b^2))`` of two zero-mean windows (1 if equal)."""
    a = np.asarray(a, dtype=float) - np.mean(a)
    b = np.asarray(b, dtype=float) - np.mean(b)
    den = float(np.sum(a * a) + np.sum(b * b))
    return 2.0 * float(np.sum(a * b)) / den if den > 0 else 0.0


@dataclass(frozen=True)
class BiquadraticPeak:
    """Peak of ``f(x, y) = c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2`` fitted to 3x3 scores."""

    offset_xy: np.ndarray  # (2,) sub-pixel offset of the peak from the centre sample (x = column, y = row)
    hessian: np.ndarray  # (2, 2) second derivatives [[f_xx, f_xy], [f_xy, f_yy]] (negative definite at a peak)
    value: float
    ok: bool


def fit_biquadratic_peak(s: np.ndarray) -> BiquadraticPeak:
    """Closed-form least-squares biquadratic through 3x3 correlation scores ``s[row, col]``."""
    (s00, s01, s02), (s10, s11, s12), (s20, s21, s22) = np.asarray(s, dtype=float).tolist()
    col0, col1, col2 = s00 + s10 + s20, s01 + s11 + s21, s02 + s12 + s22  # sums over rows for x = -1, 0, 1
    row0, row1, row2 = s00 + s01 + s02, s10 + s11 + s12, s20 + s21 + s22  # sums over columns for y = -1, 0, 1
    c1, c2 = (col2 - col0) / 6.0, (row2 - row0) / 6.0
    c3 = (col0 + col2) / 6.0 - col1 / 3.0
    c5 = (row0 + row2) / 6.0 - row1 / 3.0
    c4 = (s00 - s02 - s20 + s22) / 4.0
    c0 = (5.0 * (col0 + col1 + col2) - 3.0 * (col0 + col2 + row0 + row2)) / 9.0
    hxx, hyy, hxy = 2.0 * c3, 2.0 * c5, c4
    hess = np.array([[hxx, hxy], [hxy, hyy]])
    det = hxx * hyy - hxy * hxy
    if not (hxx < 0 and det > 0):
        return BiquadraticPeak(np.zeros(2), hess, s11, False)
    off = np.array([-(hyy * c1 - hxy * c2) / det, -(hxx * c2 - hxy * c1) / det])  # -H^-1 g
    value = c0 + 0.5 * (c1 * off[0] + c2 * off[1])
    return BiquadraticPeak(off, hess, value, bool(abs(off[0]) <= 1.0 and abs(off[1]) <= 1.0))


@dataclass(frozen=True)
class WindowStats:
    """An image with per-pixel window sums, so each match needs only one ``matchTemplate`` call.

    ``coarse`` optionally holds the same for the image reduced by 2 (``cv2.pyrDown``: coarse pixel ``(i, j)`` is
    full-resolution pixel ``(2i, 2j)``), used for coarse-to-fine tracking.
    """

    img: np.ndarray  # float32
    energy: np.ndarray  # float64: sum of squared zero-mean values in the window centred on each pixel
    window_px: int
    coarse: WindowStats | None = None


def window_stats(img: np.ndarray, window_px: int, coarse: bool = False) -> WindowStats:
    f = _as_f32(img)
    d = f.astype(np.float64)
    s1 = cv2.boxFilter(d, -1, (window_px, window_px), normalize=False, borderType=cv2.BORDER_REFLECT)
    s2 = cv2.boxFilter(d * d, -1, (window_px, window_px), normalize=False, borderType=cv2.BORDER_REFLECT)
    half = window_stats(cv2.pyrDown(f), window_px) if coarse else None
    return WindowStats(f, np.maximum(s2 - s1 * s1 / window_px**2, 0.0), window_px, half)


@dataclass(frozen=True)
class Match:
    """A correlation match of one window: sub-pixel position, score and position covariance."""

    uv: np.ndarray  # (2,)
    score: float
    cov_px2: np.ndarray  # (2, 2) covariance of the relative position of the two windows
    ok: bool


_NO_MATCH = Match(np.full(2, np.nan), 0.0, np.full((2, 2), np.nan), False)


def correlate_window(
    template: np.ndarray,
    search: WindowStats,
    u_range: tuple[int, int],
    v_range: tuple[int, int],
    params: VoParams,
    min_score: float,
) -> Match:
    """Search window centres ``u in u_range, v in v_range`` (inclusive) of ``search`` for ``template``.

    Score: pseudo-normalised correlation of zero-mean windows. Sub-pixel: biquadratic on the 3x3 scores around
    the best integer centre, which must be a local maximum. Covariance of the position, from the peak
    curvature: ``score ~= 1 - SSD / (sum a^2 + sum b^2)``, so with grey-level noise sigma_n in both images the
    least-squares match covariance ``2 sigma_n^2 (sum g g^T)^-1`` becomes ``4 sigma_n^2 / (sum a^2 + sum b^2)
    * (-H)^-1``, H the fitted Hessian of the score; a floor ``min_match_sigma_px`` accounts for interpolation
    bias.
    """
    h = search.window_px // 2
    img_h, img_w = search.img.shape
    t64 = template.astype(np.float64)
    a64 = t64 - t64.mean()
    ea = float(np.dot(a64.ravel(), a64.ravel()))
    a = a64.astype(np.float32)
    if ea < (params.min_window_std_grey**2) * a.size:
        return _NO_MATCH
    # score map over the searched centres plus a one-pixel rim for the 3x3 fit, clipped to valid centres
    u0, u1 = max(u_range[0] - 1, h), min(u_range[1] + 1, img_w - 1 - h)
    v0, v1 = max(v_range[0] - 1, h), min(v_range[1] + 1, img_h - 1 - h)
    if u1 - u0 < 2 or v1 - v0 < 2:
        return _NO_MATCH
    strip = search.img[v0 - h : v1 + h + 1, u0 - h : u1 + h + 1]
    sab = cv2.matchTemplate(strip, a, cv2.TM_CCORR).astype(np.float64)
    eb = search.energy[v0 : v1 + 1, u0 : u1 + 1]
    den = ea + eb
    score = np.where(den > 0, 2.0 * sab / np.where(den > 0, den, 1.0), 0.0)
    inner = score[1:-1, 1:-1]
    r, c = np.unravel_index(int(np.argmax(inner)), inner.shape)
    r, c = r + 1, c + 1
    best = float(score[r, c])
    nb = score[r - 1 : r + 2, c - 1 : c + 2]
    if best < min_score or best < float(nb.max()):
        return _NO_MATCH
    pk = fit_biquadratic_peak(nb)
    if not pk.ok:
        return _NO_MATCH
    uv = np.array([u0 + c + pk.offset_xy[0], v0 + r + pk.offset_xy[1]])
    k = 4.0 * params.image_noise_grey**2 / float(den[r, c])
    (hxx, hxy), (_, hyy) = pk.hessian.tolist()
    det = hxx * hyy - hxy * hxy
    cov = (k / det) * np.array([[-hyy, hxy], [hxy, -hxx]]) + params.min_match_sigma_px**2 * np.eye(2)  # k (-H)^-1
    return Match(uv, min(pk.value, 1.0), cov, True)


def window_at(img: np.ndarray, uv: np.ndarray, window_px: int) -> np.ndarray | None:
    """The ``window_px`` square window centred on integer pixel ``uv``, or None if it leaves the image."""
    h = window_px // 2
    u, v = int(round(uv[0])), int(round(uv[1]))
    if u - h < 0 or v - h < 0 or u + h >= img.shape[1] or v + h >= img.shape[0]:
        return None
    return img[v - h : v + h + 1, u - h : u + h + 1]


@dataclass(frozen=True)
class StereoMatches:
    """Step 2 output: left features and their right-image matches (rectified pair)."""

    uv_left: np.ndarray  # (N, 2)
    uv_right: np.ndarray  # (N, 2) sub-pixel; NaN where no match
    cov_left_px2: np.ndarray  # (N, 2, 2)
    cov_right_px2: np.ndarray  # (N, 2, 2)
    score: np.ndarray  # (N,)
    valid: np.ndarray  # (N,) bool


def stereo_match_features(
    left: np.ndarray | WindowStats,
    right: np.ndarray | WindowStats,
    uv: np.ndarray,
    params: VoParams,
    disparity_range_px: np.ndarray | None = None,
) -> StereoMatches:
    """Step 2: match left features ``uv`` (integer pixels) along the epipolar line (+- ``row_slack_px`` rows).

    ``disparity_range_px`` (N, 2) limits each search to ``[d_min, d_max]`` (used when re-matching tracked
    features whose 3D position is known); default ``[min_disparity_px, max_disparity_px]``. The match
    covariance (see :func:`correlate_window`) covers the noise of both images; it is split equally between the
    left and right positions.
    """
    ls = left if isinstance(left, WindowStats) else window_stats(left, params.window_px)
    rs = right if isinstance(right, WindowStats) else window_stats(right, params.window_px)
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    n = len(uv)
    uv_r = np.full((n, 2), np.nan)
    cov = np.full((n, 2, 2), np.nan)
    score = np.zeros(n)
    valid = np.zeros(n, bool)
    for i in range(n):
        tmpl = window_at(ls.img, uv[i], params.window_px)
        if tmpl is None:
            continue
        u, v = int(round(uv[i, 0])), int(round(uv[i, 1]))
        if disparity_range_px is None:
            d0, d1 = params.min_disparity_px, params.max_disparity_px
        else:
            d0, d1 = int(np.floor(disparity_range_px[i, 0])), int(np.ceil(disparity_range_px[i, 1]))
            d0 = max(d0, 0)
            if d1 < d0:
                continue
        m = correlate_window(
            tmpl,
            rs,
            (u - d1, u - d0),
            (v - params.row_slack_px, v + params.row_slack_px),
            params,
            params.min_correlation,
        )
        if not m.ok:
            continue
        uv_r[i], cov[i], score[i], valid[i] = m.uv, m.cov_px2, m.score, True
    return StereoMatches(uv.copy(), uv_r, cov / 2.0, cov / 2.0, score, valid)


def _as_f32(img: np.ndarray) -> np.ndarray:
    a = np.asarray(img)
    if a.ndim != 2:
        raise ValueError(f"expected a greyscale image (H, W), got shape {a.shape}; convert colour images first")
    return a.astype(np.float32, copy=False)
