"""DIMES: Descent Image Motion Estimation, the MER landers' horizontal-velocity sensor (pure numpy/scipy/OpenCV).

As flown (Maimone et al., "Autonomous Navigation Results from the MER Mission", section 2; REFERENCE.md section 6),
:func:`estimate_velocity` reads as these steps:

1. **Altitudes**: the radar altimeter's heights at the three images, smoothed by a least-squares fit to one flat
   ground under a constant-vertical-velocity descent plus the IMU's vertical motion (:func:`fit_altitudes`).
2. **Pair 1-2**: an interest operator picks features in image 1 inside the *search window* (the part of image 1
   that the attitude, altitude and the largest expected drift keep in view of image 2); each is matched in image
   2 by multi-resolution correlation, its template first *warped* by the ground-plane homography of the two
   views (IMU attitude, radar altitude, predicted drift) so it looks as it will in image 2
   (:func:`plane_homography`, :func:`match_feature`); consistency checks validate each match; each match gives
   a ground displacement and so a mean velocity over the interval (:func:`pair_velocity`).
3. **Pair 2-3**: the same from image 2 to image 3, its search centred on the drift predicted from pair 1-2 and
   the IMU, and narrower.
4. **Acceleration check**: the two mean velocities give an acceleration, compared with the IMU's.
5. **Velocity at the last image**: each pair's mean velocity minus the IMU's mean velocity change over it gives
   the velocity at the first image; their mean plus the IMU velocity change to the last image is the output.
6. **Decision**: fire the side thrusters (TIRS) if the horizontal speed exceeds ``tirs_threshold_mps``.

Any failed check means *no estimate* (``DimesResult.valid`` false; flight then left TIRS to its attitude-only
logic): a wrong velocity would fire TIRS the wrong way, a missing one only forgoes the correction.

Flight structure kept, with one documented extension: flight picked two features per image (the onboard computer
allowed no more); ``DimesParams.features_per_image`` (default 2 = flight) may be raised for robustness, and the
feature-agreement check then asks for the largest group of mutually agreeing features to hold at least two
features and a majority of the matched ones.

Geometry: a flat ground plane ``z = 0`` in the local-level frame (x east, y north, z up); camera ``k`` at
``(x_k, y_k, h_k)``, ``h_k`` its height above the plane, attitude ``R_world_cam`` (OpenCV camera axes, from the IMU).
A ground point ``(X, Y, 0)`` images at ``K R^T [e1 e2 -c] (X, Y, 1)^T``, so two views of the plane are related
by a homography. Pixels: ``u`` column, ``v`` row, the centre of the top-left pixel at (0, 0) (OpenCV).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from nav.camera import PinholeCamera
from nav.vo.features import fit_biquadratic_peak

# ------------------------------------------------------------------------------------------------- types


@dataclass(frozen=True)
class DescentImage:
    """One descent image with the IMU and radar data at its time (everything the flight software had).

    ``imu_delta_v_mps`` and ``imu_delta_p_m`` integrate the accelerometers from the first image of the sequence
    (time ``t0``) in the local-level frame: ``v(t) - v(t0)`` and ``p(t) - p(t0) - v(t0) (t - t0)``.
    """

    t_s: float
    image: np.ndarray  # (H, W) uint8 greyscale
    camera: PinholeCamera  # intrinsics of this (binned) image
    R_world_cam: np.ndarray  # (3, 3) IMU attitude of the camera, OpenCV axes, local level frame
    altitude_m: float  # radar altimeter: height above the ground
    imu_delta_v_mps: np.ndarray  # (3,)
    imu_delta_p_m: np.ndarray  # (3,)


@dataclass(frozen=True)
class DimesParams:
    """Every threshold of DIMES. Defaults are for 256x256 images (MER descent camera binned from 1024^2)."""

    # --- interest operator ---
    features_per_image: int = 2  # flight: two per image
    template_px: int = 15  # correlation window (odd): about 70-100 m of ground at 1400-2000 m
    # Shi-Tomasi interest: the smaller eigenvalue of the grey-level gradient's second-moment matrix averaged over
    # the template ((grey level / px)^2). Below this, the window has no 2-D structure (flat, or a straight edge).
    min_interest: float = 2.0
    min_template_std_grey: float = 3.0  # a window with less contrast than this is featureless
    min_feature_spacing_frac: float = 0.25  # of the image width: the features come from different parts
    # --- multi-resolution correlation ---
    pyramid_levels: int = 2  # correlation at 1/2 resolution over the whole search window, then full resolution
    max_speed_mps: float = 35.0  # pair 1-2 search window: any drift up to this speed (winds <= ~20 m/s + swing)
    prior_speed_sigma_mps: float = 3.0  # pair 2-3 search: +-4 sigma around the drift predicted from pair 1-2
    search_margin_px: int = 2  # added to each search radius (attitude error, rounding)
    refine_radius_px: int = 3  # search at each finer level around the coarser match (+-1.5 coarse px)
    # --- consistency checks ---
    min_correlation: float = 0.8  # normalised correlation of the full-resolution match
    max_second_peak_ratio: float = 0.9  # another local peak in the search window at >= this x the best: ambiguous
    second_peak_exclusion_px: int = 2  # (at the coarse level) peaks this close to the best are the same peak
    min_peak_curvature: float = 0.01  # -(second derivative) of the score along the flattest direction, per px^2
    max_feature_disagreement_mps: float = 2.0  # velocities from the features of one pair must agree this well
    max_accel_disagreement_mps2: float = 0.6  # |DIMES acceleration - IMU acceleration|
    # --- altitude ---
    fit_altitudes: bool = True  # smooth the radar heights with the IMU's vertical motion (step 1)
    # --- decision ---
    tirs_threshold_mps: float = 10.0  # fire TIRS above this horizontal speed (assumed; flight logic not public)

    def __post_init__(self) -> None:
        if self.template_px % 2 == 0 or self.template_px < 5:
            raise ValueError(f"template_px must be odd and >= 5, got {self.template_px}")
        if self.features_per_image < 2:
            raise ValueError("features_per_image must be >= 2: the agreement check needs two features")
        if self.pyramid_levels < 1:
            raise ValueError(f"pyramid_levels must be >= 1, got {self.pyramid_levels}")


@dataclass(frozen=True)
class FeatureMatch:
    """One feature of image i and its correlation match in image j."""

    uv_i: np.ndarray  # (2,) feature in image i
    uv_j: np.ndarray  # (2,) match in image j (NaN if none)
    interest: float
    correlation: float  # full-resolution normalised correlation at the peak
    second_peak_ratio: float  # best other local peak / best, coarse level
    curvature: float  # smallest -(second derivative) of the score at the peak
    displacement_m: np.ndarray  # (2,) horizontal camera displacement from i to j implied by this match
    ok: bool
    reason: str = ""  # "" if ok, else the failed check


@dataclass(frozen=True)
class PairEstimate:
    """The mean horizontal velocity over one image pair, from its features."""

    i: int
    j: int
    dt_s: float
    velocity_mps: np.ndarray | None  # (2,) mean velocity over [t_i, t_j]; None if rejected
    matches: tuple[FeatureMatch, ...]
    inliers: tuple[int, ...]  # indices into matches of the agreeing group
    ok: bool
    reason: str = ""


@dataclass(frozen=True)
class DimesResult:
    """The DIMES output: horizontal velocity at the last image and the TIRS decision, or a rejection."""

    valid: bool
    velocity_mps: np.ndarray | None  # (2,) horizontal (east, north) velocity at the last image's time
    fire_tirs: bool
    reason: str  # "" if valid, else the first failed check ("pair 1-2: no_features", "acceleration_check", ...)
    pairs: tuple[PairEstimate, ...]
    accel_dimes_mps2: np.ndarray | None = None  # (2,)
    accel_imu_mps2: np.ndarray | None = None  # (2,)
    altitudes_m: np.ndarray | None = None  # (n,) altitudes used (after the fit)
    elapsed_ms: float = 0.0

    @property
    def speed_mps(self) -> float:
        return float(np.linalg.norm(self.velocity_mps)) if self.velocity_mps is not None else math.nan


# ---------------------------------------------------------------------------------------------- geometry


def ground_to_image(camera: PinholeCamera, R_world_cam: np.ndarray, centre_m: np.ndarray) -> np.ndarray:
    """3x3 homography from ground-plane coordinates ``(X, Y, 1)`` (z = 0) to pixels, camera at ``centre_m``."""
    c = np.asarray(centre_m, dtype=float)
    return camera.K @ np.asarray(R_world_cam).T @ np.array([[1.0, 0.0, -c[0]], [0.0, 1.0, -c[1]], [0.0, 0.0, -c[2]]])


def plane_homography(
    camera_i: PinholeCamera,
    R_i: np.ndarray,
    altitude_i_m: float,
    camera_j: PinholeCamera,
    R_j: np.ndarray,
    altitude_j_m: float,
    displacement_m: np.ndarray,
) -> np.ndarray:
    """Homography from image i to image j of the ground plane, camera j displaced horizontally by
    ``displacement_m`` (2,) from camera i."""
    G_i = ground_to_image(camera_i, R_i, np.array([0.0, 0.0, altitude_i_m]))
    G_j = ground_to_image(camera_j, R_j, np.array([displacement_m[0], displacement_m[1], altitude_j_m]))
    H = G_j @ np.linalg.inv(G_i)
    return H / H[2, 2]


def ground_offset_m(camera: PinholeCamera, R_world_cam: np.ndarray, altitude_m: float, uv: np.ndarray) -> np.ndarray:
    """(N, 2) horizontal offsets from the camera to the ground points seen at pixels ``uv``; NaN above the
    horizon."""
    rays = camera.ray(uv) @ np.asarray(R_world_cam).T
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(rays[:, 2] < 0.0, altitude_m / -rays[:, 2], np.nan)
    return rays[:, :2] * s[:, None]


def apply_homography(H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    p = np.atleast_2d(np.asarray(uv, dtype=float))
    q = np.c_[p, np.ones(len(p))] @ H.T
    return q[:, :2] / q[:, 2:3]


def displacement_from_match(
    frame_i: DescentImage, h_i: float, frame_j: DescentImage, h_j: float, uv_i: np.ndarray, uv_j: np.ndarray
) -> np.ndarray:
    """Horizontal camera displacement (2,) from i to j that puts the ground point seen at ``uv_i`` in image i
    at ``uv_j`` in image j: ``offset_i(uv_i) - offset_j(uv_j)``."""
    g_i = ground_offset_m(frame_i.camera, frame_i.R_world_cam, h_i, uv_i)[0]
    g_j = ground_offset_m(frame_j.camera, frame_j.R_world_cam, h_j, uv_j)[0]
    return g_i - g_j


def fit_altitudes(frames: Sequence[DescentImage]) -> np.ndarray:
    """Radar heights smoothed by a least-squares fit to ``h_k = h_0 + w (t_k - t_0) + dz_k``: one flat ground, an
    unknown vertical velocity ``w`` at the first image, and the IMU's vertical position change ``dz_k``."""
    t = np.array([f.t_s for f in frames]) - frames[0].t_s
    dz = np.array([f.imu_delta_p_m[2] for f in frames])
    h = np.array([f.altitude_m for f in frames])
    if len(frames) < 3:
        return h
    A = np.c_[np.ones_like(t), t]
    coef, *_ = np.linalg.lstsq(A, h - dz, rcond=None)
    return A @ coef + dz


# ------------------------------------------------------------------------------------------------ features


def interest_image(image: np.ndarray, window_px: int) -> np.ndarray:
    """Shi-Tomasi interest per pixel: the smaller eigenvalue of the mean gradient outer product over the
    ``window_px`` square window centred there, in (grey level / px)^2."""
    f = image.astype(np.float32)
    gx = cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3, scale=1.0 / 8.0)
    gy = cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3, scale=1.0 / 8.0)
    k = (window_px, window_px)
    sxx = cv2.boxFilter(gx * gx, -1, k, borderType=cv2.BORDER_REFLECT)
    syy = cv2.boxFilter(gy * gy, -1, k, borderType=cv2.BORDER_REFLECT)
    sxy = cv2.boxFilter(gx * gy, -1, k, borderType=cv2.BORDER_REFLECT)
    half_trace = 0.5 * (sxx + syy)
    return half_trace - np.sqrt(np.maximum(0.25 * (sxx - syy) ** 2 + sxy * sxy, 0.0))


def window_std(image: np.ndarray, window_px: int) -> np.ndarray:
    f = image.astype(np.float64)
    k = (window_px, window_px)
    m1 = cv2.boxFilter(f, -1, k, borderType=cv2.BORDER_REFLECT)
    m2 = cv2.boxFilter(f * f, -1, k, borderType=cv2.BORDER_REFLECT)
    return np.sqrt(np.maximum(m2 - m1 * m1, 0.0))


def search_window_mask(
    shape: tuple[int, int], H_ij: np.ndarray, shape_j: tuple[int, int], margin_i_px: float, margin_j_px: float
) -> np.ndarray:
    """Pixels of image i at least ``margin_i_px`` inside it whose predicted position ``H_ij`` in image j is at least
    ``margin_j_px`` inside image j: where a feature can be matched without its search leaving image j."""
    h, w = shape
    vv, uu = np.mgrid[0:h, 0:w]
    q = apply_homography(H_ij, np.c_[uu.ravel(), vv.ravel()]).reshape(h, w, 2)
    hj, wj = shape_j
    inside_i = (uu >= margin_i_px) & (uu <= w - 1 - margin_i_px) & (vv >= margin_i_px) & (vv <= h - 1 - margin_i_px)
    inside_j = (
        (q[..., 0] >= margin_j_px)
        & (q[..., 0] <= wj - 1 - margin_j_px)
        & (q[..., 1] >= margin_j_px)
        & (q[..., 1] <= hj - 1 - margin_j_px)
    )
    return inside_i & inside_j


def select_features(image: np.ndarray, mask: np.ndarray, params: DimesParams) -> tuple[np.ndarray, np.ndarray]:
    """Interest operator: up to ``features_per_image`` pixels ``(N, 2)`` and their interest ``(N,)``, strongest
    first, inside ``mask``, at least ``min_feature_spacing_frac`` of the image width apart, each above
    ``min_interest`` and ``min_template_std_grey``."""
    score = interest_image(image, params.template_px)
    ok = mask & (score >= params.min_interest) & (window_std(image, params.template_px) >= params.min_template_std_grey)
    spacing = params.min_feature_spacing_frac * image.shape[1]
    candidates = np.flatnonzero(ok.ravel())
    order = candidates[np.argsort(-score.ravel()[candidates], kind="stable")]
    chosen: list[tuple[float, float]] = []
    scores: list[float] = []
    w = image.shape[1]
    for idx in order:
        v, u = divmod(int(idx), w)
        if all((u - cu) ** 2 + (v - cv) ** 2 >= spacing**2 for cu, cv in chosen):
            chosen.append((float(u), float(v)))
            scores.append(float(score[v, u]))
            if len(chosen) == params.features_per_image:
                break
    return np.asarray(chosen, dtype=float).reshape(-1, 2), np.asarray(scores, dtype=float)


# ------------------------------------------------------------------------------------------------ matching


def pyramid(image: np.ndarray, levels: int) -> list[np.ndarray]:
    """Float32 images at full, 1/2, 1/4 ... resolution (``cv2.pyrDown``: pixel k of level L+1 is pixel 2k of L)."""
    out = [image.astype(np.float32)]
    for _ in range(levels - 1):
        out.append(cv2.pyrDown(out[-1]))
    return out


def _scale_h(H: np.ndarray, level: int) -> np.ndarray:
    s = 0.5**level
    S = np.diag([s, s, 1.0])
    return S @ H @ np.linalg.inv(S)


def warped_template(image_i: np.ndarray, H_ij: np.ndarray, uv_i: np.ndarray, size_px: int) -> np.ndarray:
    """Template of image i around ``uv_i`` resampled as it would look in image j (``H_ij``); its centre pixel is
    ``uv_i`` exactly."""
    r = size_px // 2
    centre_j = apply_homography(H_ij, uv_i)[0]
    M = np.array([[1.0, 0.0, r - centre_j[0]], [0.0, 1.0, r - centre_j[1]], [0.0, 0.0, 1.0]]) @ H_ij
    return cv2.warpPerspective(image_i, M, (size_px, size_px), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


@dataclass(frozen=True)
class _Scores:
    scores: np.ndarray  # (2R+1, 2R+1) normalised correlation of template centres around ``centre``
    centre: np.ndarray  # (2,) integer pixel of the score map's middle
    radius: int
    clipped: bool  # the search region left the image (padded)


def _correlate(image_j: np.ndarray, template: np.ndarray, centre: np.ndarray, radius: int) -> _Scores:
    """Normalised correlation (``TM_CCOEFF_NORMED``) of ``template`` centred at every integer pixel within
    ``radius`` of ``centre`` in ``image_j``."""
    r = template.shape[0] // 2
    c = np.rint(centre).astype(int)
    half = r + radius
    h, w = image_j.shape
    x0, x1, y0, y1 = c[0] - half, c[0] + half + 1, c[1] - half, c[1] + half + 1
    pads = (max(0, -y0), max(0, y1 - h), max(0, -x0), max(0, x1 - w))
    region = image_j[max(y0, 0) : min(y1, h), max(x0, 0) : min(x1, w)]
    if any(pads):
        if region.size == 0:
            return _Scores(np.full((2 * radius + 1,) * 2, -1.0, np.float32), c, radius, True)
        region = cv2.copyMakeBorder(region, *pads, cv2.BORDER_REPLICATE)
    scores = cv2.matchTemplate(region, template, cv2.TM_CCOEFF_NORMED)
    return _Scores(np.nan_to_num(scores, nan=-1.0), c, radius, any(pads))


def _second_peak_ratio(scores: np.ndarray, best_rc: tuple[int, int], exclusion_px: int) -> float:
    """Best other local maximum of the score map (farther than ``exclusion_px`` from the best) over the best."""
    best = float(scores[best_rc])
    local_max = scores >= cv2.dilate(scores, np.ones((3, 3), np.uint8))
    rr, cc = np.nonzero(local_max)
    far = np.maximum(np.abs(rr - best_rc[0]), np.abs(cc - best_rc[1])) > exclusion_px
    if not np.any(far) or best <= 0.0:
        return 0.0 if best > 0.0 else 1.0
    return float(max(scores[rr[far], cc[far]].max(), 0.0) / best)


@dataclass(frozen=True)
class _Peak:
    uv: np.ndarray
    correlation: float
    curvature: float
    ok: bool
    reason: str


def _fine_peak(image_j: np.ndarray, template: np.ndarray, centre: np.ndarray, radius: int) -> _Peak:
    """Integer search within ``radius`` then a biquadratic sub-pixel fit on the 3x3 scores around the best."""
    s = _correlate(image_j, template, centre, radius)
    r, c = np.unravel_index(int(np.argmax(s.scores)), s.scores.shape)
    best = float(s.scores[r, c])
    uv = s.centre + np.array([c - radius, r - radius], dtype=float)
    if s.clipped:
        return _Peak(uv, best, 0.0, False, "search_leaves_image")
    if min(r, c) == 0 or max(r, c) == 2 * radius:
        return _Peak(uv, best, 0.0, False, "peak_at_window_edge")
    pk = fit_biquadratic_peak(s.scores[r - 1 : r + 2, c - 1 : c + 2])
    curvature = float(-np.linalg.eigvalsh(pk.hessian).max())
    if not pk.ok:
        return _Peak(uv, best, curvature, False, "flat_peak")
    return _Peak(uv + pk.offset_xy, min(float(pk.value), 1.0), curvature, True, "")


def match_feature(
    pyr_i: list[np.ndarray],
    pyr_j: list[np.ndarray],
    uv_i: np.ndarray,
    H_ij: np.ndarray,
    radius_px: float,
    params: DimesParams,
) -> tuple[np.ndarray, float, float, float, str]:
    """Multi-resolution correlation of the feature ``uv_i`` of image i in image j.

    At the coarsest level the template (warped by ``H_ij``) is correlated over the whole search window
    (``radius_px`` full-resolution pixels around the predicted position); each finer level searches
    ``refine_radius_px`` around the coarser match; the finest gives a sub-pixel peak. Returns
    ``(uv_j, correlation, second_peak_ratio, curvature, reason)``, ``reason`` "" if every check passed.
    """
    T = params.template_px
    top = len(pyr_i) - 1
    estimate = apply_homography(H_ij, uv_i)[0]
    ratio = 0.0
    for level in range(top, 0, -1):
        s = 0.5**level
        H_l = _scale_h(H_ij, level)
        tpl = warped_template(pyr_i[level], H_l, uv_i * s, T)
        radius = (math.ceil(radius_px * s) + 1) if level == top else params.refine_radius_px
        sc = _correlate(pyr_j[level], tpl, estimate * s, radius)
        r, c = np.unravel_index(int(np.argmax(sc.scores)), sc.scores.shape)
        if level == top:
            if sc.clipped:
                return estimate, 0.0, 1.0, 0.0, "search_leaves_image"
            ratio = _second_peak_ratio(sc.scores, (int(r), int(c)), params.second_peak_exclusion_px)
            if ratio > params.max_second_peak_ratio:
                return estimate, float(sc.scores[r, c]), ratio, 0.0, "ambiguous_peak"
            if r in (0, 2 * radius) or c in (0, 2 * radius):
                return estimate, float(sc.scores[r, c]), ratio, 0.0, "peak_at_window_edge"
        estimate = (sc.centre + np.array([c - radius, r - radius], dtype=float)) / s
    radius0 = math.ceil(radius_px) + 1 if top == 0 else params.refine_radius_px
    if top == 0:
        sc = _correlate(pyr_j[0], warped_template(pyr_i[0], H_ij, uv_i, T), estimate, radius0)
        r, c = np.unravel_index(int(np.argmax(sc.scores)), sc.scores.shape)
        ratio = _second_peak_ratio(sc.scores, (int(r), int(c)), params.second_peak_exclusion_px)
    pk = _fine_peak(pyr_j[0], warped_template(pyr_i[0], H_ij, uv_i, T), estimate, radius0)
    return pk.uv, pk.correlation, ratio, pk.curvature, pk.reason


def check_match(correlation: float, ratio: float, curvature: float, reason: str, params: DimesParams) -> str:
    """The correlation checks: peak height, uniqueness, sharpness (and the search's own failures)."""
    if reason:
        return reason
    if correlation < params.min_correlation:
        return "low_correlation"
    if ratio > params.max_second_peak_ratio:
        return "ambiguous_peak"
    if curvature < params.min_peak_curvature:
        return "flat_peak"
    return ""


def agreeing_group(velocities: np.ndarray, tol: float) -> tuple[int, ...]:
    """Indices of the largest group of velocities all within ``tol`` of its seed member (ties: first seed)."""
    best: tuple[int, ...] = ()
    for k in range(len(velocities)):
        group = tuple(int(i) for i in np.flatnonzero(np.linalg.norm(velocities - velocities[k], axis=1) <= tol))
        if len(group) > len(best):
            best = group
    return best


def pair_velocity(
    frames: Sequence[DescentImage],
    i: int,
    j: int,
    altitudes_m: np.ndarray,
    prior_displacement_m: np.ndarray,
    radius_m: float,
    params: DimesParams,
) -> PairEstimate:
    """Mean horizontal velocity over images ``i`` -> ``j``: features of i matched in j (steps 2 and 3)."""
    fi, fj = frames[i], frames[j]
    h_i, h_j = float(altitudes_m[i]), float(altitudes_m[j])
    dt = fj.t_s - fi.t_s
    H = plane_homography(fi.camera, fi.R_world_cam, h_i, fj.camera, fj.R_world_cam, h_j, prior_displacement_m)
    radius_px = fj.camera.fx_px * radius_m / h_j + params.search_margin_px
    top = params.pyramid_levels - 1
    r = params.template_px // 2
    margin_j = (r + math.ceil(radius_px / 2**top) + 1) * 2**top + 1
    mask = search_window_mask(fi.image.shape, H, fj.image.shape, r + 1, margin_j)
    uv, interest = select_features(fi.image, mask, params)
    if len(uv) < 2:
        return PairEstimate(i, j, dt, None, (), (), False, "no_features")

    pyr_i, pyr_j = pyramid(fi.image, params.pyramid_levels), pyramid(fj.image, params.pyramid_levels)
    matches = []
    for k in range(len(uv)):
        uv_j, corr, ratio, curv, reason = match_feature(pyr_i, pyr_j, uv[k], H, radius_px, params)
        reason = check_match(corr, ratio, curv, reason, params)
        if not reason:
            # refinement: re-warp the template with this match's own displacement and correlate again (+-2 px)
            disp = displacement_from_match(fi, h_i, fj, h_j, uv[k : k + 1], uv_j[None])
            H_k = plane_homography(fi.camera, fi.R_world_cam, h_i, fj.camera, fj.R_world_cam, h_j, disp)
            pk = _fine_peak(pyr_j[0], warped_template(pyr_i[0], H_k, uv[k], params.template_px), uv_j,
                            params.refine_radius_px)  # fmt: skip
            uv_j, corr, curv = pk.uv, pk.correlation, pk.curvature
            reason = check_match(corr, ratio, curv, pk.reason, params)
        disp = (
            displacement_from_match(fi, h_i, fj, h_j, uv[k : k + 1], uv_j[None]) if not reason else np.full(2, np.nan)
        )
        matches.append(FeatureMatch(uv[k], uv_j, float(interest[k]), corr, ratio, curv, disp, not reason, reason))

    good = [k for k, m in enumerate(matches) if m.ok]
    if len(good) < 2:
        first = next((m.reason for m in matches if not m.ok), "no_match")
        return PairEstimate(i, j, dt, None, tuple(matches), (), False, first)
    vel = np.array([matches[k].displacement_m for k in good]) / dt
    group = agreeing_group(vel, params.max_feature_disagreement_mps)
    if len(group) < 2 or 2 * len(group) <= len(good):  # at least two, and a strict majority of the matches
        return PairEstimate(i, j, dt, None, tuple(matches), (), False, "features_disagree")
    inliers = tuple(good[g] for g in group)
    return PairEstimate(i, j, dt, vel[list(group)].mean(axis=0), tuple(matches), inliers, True)


# ------------------------------------------------------------------------------------------------ estimator


def estimate_velocity(frames: Sequence[DescentImage], params: DimesParams | None = None) -> DimesResult:
    """DIMES on three descent images (see the module docstring for the steps)."""
    params = params or DimesParams()
    t_start = time.perf_counter()
    if len(frames) != 3:
        raise ValueError(f"DIMES takes three descent images, got {len(frames)}")

    # 1. altitudes
    alt = fit_altitudes(frames) if params.fit_altitudes else np.array([f.altitude_m for f in frames])
    imu_p = np.array([f.imu_delta_p_m[:2] for f in frames])
    imu_v = np.array([f.imu_delta_v_mps[:2] for f in frames])

    def reject(reason: str, pairs: tuple[PairEstimate, ...], **extra) -> DimesResult:
        ms = 1e3 * (time.perf_counter() - t_start)
        return DimesResult(False, None, False, reason, pairs, altitudes_m=alt, elapsed_ms=ms, **extra)

    # 2. pair 1-2: no prior drift; the search window covers any speed up to max_speed_mps
    dt12 = frames[1].t_s - frames[0].t_s
    p12 = pair_velocity(frames, 0, 1, alt, np.zeros(2), params.max_speed_mps * dt12, params)
    if not p12.ok:
        return reject(f"pair 1-2: {p12.reason}", (p12,))
    v0_12 = p12.velocity_mps - (imu_p[1] - imu_p[0]) / dt12  # velocity at image 1 implied by pair 1-2

    # 3. pair 2-3: predicted drift from pair 1-2 and the IMU, narrower search
    dt23 = frames[2].t_s - frames[1].t_s
    prior = v0_12 * dt23 + (imu_p[2] - imu_p[1])
    p23 = pair_velocity(frames, 1, 2, alt, prior, 4.0 * params.prior_speed_sigma_mps * dt23, params)
    if not p23.ok:
        return reject(f"pair 2-3: {p23.reason}", (p12, p23))
    v0_23 = p23.velocity_mps - (imu_p[2] - imu_p[1]) / dt23

    # 4. acceleration check: DIMES mean velocities vs the IMU's over the same intervals
    dt_mid = 0.5 * (frames[2].t_s - frames[0].t_s)
    acc_dimes = (p23.velocity_mps - p12.velocity_mps) / dt_mid
    acc_imu = ((imu_p[2] - imu_p[1]) / dt23 - (imu_p[1] - imu_p[0]) / dt12) / dt_mid
    pairs = (p12, p23)
    if np.linalg.norm(acc_dimes - acc_imu) > params.max_accel_disagreement_mps2:
        return reject("acceleration_check", pairs, accel_dimes_mps2=acc_dimes, accel_imu_mps2=acc_imu)

    # 5. velocity at the last image
    v_last = 0.5 * (v0_12 + v0_23) + imu_v[2]

    # 6. decision
    fire = bool(np.linalg.norm(v_last) > params.tirs_threshold_mps)
    ms = 1e3 * (time.perf_counter() - t_start)
    return DimesResult(True, v_last, fire, "", pairs, acc_dimes, acc_imu, alt, ms)
