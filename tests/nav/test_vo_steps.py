"""Each step of the MER visual odometry in isolation, against synthetic ground truth (Cheng et al. 2005, sec. 2)."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from vo_synth import make_rig, motion_error

from nav.geometry import rpy_to_R, se3, se3_inv, so3_exp
from nav.vo import (
    SanityConstraints,
    VoParams,
    detect_features,
    feature_covariance,
    fit_biquadratic_peak,
    ml_refine,
    pseudo_normalized_correlation,
    ransac_motion,
    sanity_check,
    stereo_match_features,
    triangulate_rays,
    triangulate_stereo,
)
from nav.vo.motion import gap_test, motion_from_RT

RIG = make_rig()


def _textured_image(seed: int = 0, blur_px: float = 1.2, size: int = 256) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = cv2.GaussianBlur(rng.standard_normal((size, size)), (0, 0), blur_px)
    return 128.0 + 40.0 * base / base.std()


def _shift(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """Content moved by (dx, dy) px (exact band-limited shift, periodic)."""
    fy = np.fft.fftfreq(img.shape[0])[:, None]
    fx = np.fft.fftfreq(img.shape[1])[None, :]
    return np.real(np.fft.ifft2(np.fft.fft2(img) * np.exp(-2j * np.pi * (fx * dx + fy * dy))))


def _points_in_view(rng: np.random.Generator, n: int, ranges_m=(1.5, 5.0)) -> np.ndarray:
    """Rover-frame points spread over the left camera's view."""
    uv = rng.uniform(20, 236, size=(n, 2))
    depth = rng.uniform(*ranges_m, size=n)
    rays = RIG.left.ray(uv)
    X = rays * (depth / rays[:, 2])[:, None]
    T = RIG.left.T_rover_cam
    return X @ T[:3, :3].T + T[:3, 3]


def _project(cam, P_rover: np.ndarray) -> np.ndarray:
    T = se3_inv(cam.T_rover_cam)
    return cam.project(P_rover @ T[:3, :3].T + T[:3, 3])


# ---- step 3: triangulation ------------------------------------------------------------------------------------
def test_triangulation_exact_with_noise_free_rays():
    rng = np.random.default_rng(1)
    P = rng.uniform([-2, -2, 1], [2, 2, 8], size=(200, 3))
    C1, C2 = np.array([0.1, 0.2, 0.3]), np.array([0.1, -0.1, 0.35])
    r1 = (P - C1) / np.linalg.norm(P - C1, axis=1, keepdims=True)
    r2 = (P - C2) / np.linalg.norm(P - C2, axis=1, keepdims=True)
    tri = triangulate_rays(C1, r1, C2, r2)
    assert tri.ok.all()
    np.testing.assert_allclose(tri.points, P, atol=1e-9)
    np.testing.assert_allclose(tri.gap_m, 0.0, atol=1e-9)
    np.testing.assert_allclose(tri.m1, np.linalg.norm(P - C1, axis=1), rtol=1e-9)


def test_triangulation_of_stereo_pixels_recovers_points():
    P = _points_in_view(np.random.default_rng(2), 100)
    tri = triangulate_stereo(RIG, _project(RIG.left, P), _project(RIG.right, P))
    np.testing.assert_allclose(tri.points, P, atol=1e-9)
    assert gap_test(tri, RIG, max_gap_px=0.01, max_range_m=30).all()


def test_gap_test_rejects_skewed_rays():
    P = _points_in_view(np.random.default_rng(3), 50)
    uv_l, uv_r = _project(RIG.left, P), _project(RIG.right, P)
    skewed = uv_r + [0.0, 3.0]  # 3 rows off the epipolar line: the rays pass each other
    tri = triangulate_stereo(RIG, uv_l, skewed)
    assert (tri.gap_m > 0).all()
    assert not gap_test(tri, RIG, max_gap_px=1.0, max_range_m=30).any()
    slightly = triangulate_stereo(RIG, uv_l, uv_r + [0.0, 0.3])
    assert gap_test(slightly, RIG, max_gap_px=1.0, max_range_m=30).all()


def test_parallel_or_diverging_rays_are_not_ok():
    C1, C2 = np.zeros(3), np.array([0.0, -0.2, 0.0])
    r = np.array([[1.0, 0.0, 0.0]])
    assert not triangulate_rays(C1, r, C2, r).ok[0]  # parallel
    diverging = np.array([[1.0, -0.1, 0.0]]) / np.linalg.norm([1.0, -0.1, 0.0])
    assert not triangulate_rays(C1, np.array([[1.0, 0.1, 0.0]]) / np.linalg.norm([1, 0.1, 0]), C2, diverging).ok[0]


# ---- step 4: covariance ---------------------------------------------------------------------------------------
def test_feature_covariance_matches_monte_carlo():
    rng = np.random.default_rng(4)
    P = _points_in_view(rng, 8, ranges_m=(1.5, 4.0))
    uv_l, uv_r = _project(RIG.left, P), _project(RIG.right, P)
    S_l = np.array([[0.09, 0.02], [0.02, 0.04]])
    S_r = np.array([[0.06, -0.01], [-0.01, 0.05]])
    cov = feature_covariance(RIG, uv_l, uv_r, np.tile(S_l, (8, 1, 1)), np.tile(S_r, (8, 1, 1)))
    n_mc = 4000
    nl = rng.multivariate_normal(np.zeros(2), S_l, size=(n_mc, 8))
    nr = rng.multivariate_normal(np.zeros(2), S_r, size=(n_mc, 8))
    pts = triangulate_stereo(RIG, (uv_l + nl).reshape(-1, 2), (uv_r + nr).reshape(-1, 2)).points.reshape(n_mc, 8, 3)
    for j in range(8):
        mc = np.cov(pts[:, j].T)
        sd_pred, sd_mc = np.sqrt(np.linalg.eigvalsh(cov[j])), np.sqrt(np.linalg.eigvalsh(mc))
        np.testing.assert_allclose(sd_pred, sd_mc, rtol=0.3)
        assert np.linalg.norm(mc - cov[j]) / np.linalg.norm(cov[j]) < 0.3


# ---- step 2: correlation and sub-pixel peak ------------------------------------------------------------------
def test_pseudo_normalized_correlation_values():
    a = np.random.default_rng(5).normal(size=(11, 11))
    assert pseudo_normalized_correlation(a, a) == pytest.approx(1.0)
    assert pseudo_normalized_correlation(a, a + 17.0) == pytest.approx(1.0)  # zero-mean windows
    assert pseudo_normalized_correlation(a, 2.0 * a) == pytest.approx(0.8)  # 2*2/(1+4): penalises gain
    assert pseudo_normalized_correlation(a, -a) == pytest.approx(-1.0)


def test_biquadratic_recovers_peak_of_quadratic_exactly():
    x0, y0 = 0.31, -0.22
    y, x = np.mgrid[-1:2, -1:2].astype(float)
    s = 0.9 - 0.3 * (x - x0) ** 2 - 0.1 * (x - x0) * (y - y0) - 0.2 * (y - y0) ** 2
    pk = fit_biquadratic_peak(s)
    assert pk.ok
    np.testing.assert_allclose(pk.offset_xy, [x0, y0], atol=1e-12)
    np.testing.assert_allclose(pk.hessian, [[-0.6, -0.1], [-0.1, -0.4]], atol=1e-12)
    assert pk.value == pytest.approx(0.9)


@pytest.mark.parametrize("shift_px", [0.25, 0.5, 0.75])
def test_stereo_match_recovers_fractional_shift(shift_px):
    params = VoParams()
    left = _textured_image(6)
    d = 12.0 + shift_px  # disparity: right image content moved left by d
    right = _shift(left, -d, 0.0)
    uv = detect_features(left, params)
    uv = uv[uv[:, 0] > d + params.window_px]  # the match must lie inside the right image
    st = stereo_match_features(left.astype(np.float32), right.astype(np.float32), uv, params)
    assert st.valid.mean() > 0.95
    err = st.uv_right[st.valid] - (st.uv_left[st.valid] - [d, 0.0])
    assert np.median(np.abs(err[:, 0])) < 0.05
    assert np.percentile(np.abs(err), 90) < 0.1
    assert np.all(np.linalg.eigvalsh(st.cov_right_px2[st.valid]) > 0)


def test_stereo_match_rejects_textureless_windows():
    params = VoParams()
    flat = np.full((64, 64), 100.0, np.float32) + np.random.default_rng(7).normal(0, 0.3, (64, 64)).astype(np.float32)
    st = stereo_match_features(flat, flat, np.array([[40.0, 32.0]]), params)
    assert not st.valid.any()


# ---- step 1: feature detection --------------------------------------------------------------------------------
@pytest.mark.parametrize(("max_features", "spacing"), [(150, 15.0), (60, 25.0), (400, 8.0)])
def test_detector_honours_budget_and_spacing(max_features, spacing):
    params = dataclasses.replace(VoParams(), max_features=max_features, min_spacing_px=spacing)
    img = _textured_image(8)
    uv = detect_features(img, params)
    assert 0 < len(uv) <= max_features
    d = np.linalg.norm(uv[:, None] - uv[None], axis=-1) + np.eye(len(uv)) * 1e9
    assert d.min() >= spacing - 1.0  # integer pixel disc
    b = params.border_px
    assert (uv >= b).all() and (uv <= 255 - b).all()
    # features span the image: every quadrant holds some
    q = (uv[:, 0] > 128).astype(int) + 2 * (uv[:, 1] > 128)
    assert set(q.tolist()) == {0, 1, 2, 3}


def test_detector_spreads_features_even_with_a_dominant_corner_patch():
    """A small high-contrast patch (Sols 137/141 clustering, Sol 235 shadow) must not take the whole budget."""
    params = VoParams()
    img = 128.0 + 0.1 * (_textured_image(9) - 128.0)  # weak texture everywhere
    img[100:140, 100:140] = np.where(np.indices((40, 40)).sum(0) % 8 < 4, 20.0, 235.0)  # strong checker
    uv = detect_features(img, params)
    inside = ((uv >= 95) & (uv <= 145)).all(axis=1)
    assert inside.sum() <= 12
    assert len(uv) >= 100


def test_detector_mask_is_honoured():
    params = VoParams()
    mask = np.ones((256, 256), bool)
    mask[:, :128] = False
    uv = detect_features(_textured_image(10), params, mask)
    assert len(uv) > 0 and (uv[:, 0] >= 128).all()


# ---- steps 6-7: RANSAC and maximum likelihood -----------------------------------------------------------------
def _synthetic_tracks(rng, M_true, n=150, noise_px=0.15, outlier_frac=0.3):
    """Features seen before and after a motion: pixel noise, stereo triangulation, a share of gross mismatches."""
    P_prev = _points_in_view(rng, n, ranges_m=(1.5, 6.0))
    T_cur_prev = se3_inv(M_true)
    P_cur_true = P_prev @ T_cur_prev[:3, :3].T + T_cur_prev[:3, 3]
    S = np.tile(np.eye(2) * noise_px**2, (n, 1, 1))

    def observe(P):
        uv_l = _project(RIG.left, P) + rng.normal(0, noise_px, (n, 2))
        uv_r = _project(RIG.right, P) + rng.normal(0, noise_px, (n, 2))
        return uv_l, uv_r

    uv_pl, uv_pr = observe(P_prev)
    uv_cl, uv_cr = observe(P_cur_true)
    bad = rng.random(n) < outlier_frac
    jump = rng.uniform(3, 15, (n, 1)) * rng.choice([-1, 1], (n, 2))
    uv_cl[bad] += jump[bad]
    uv_cr[bad] += jump[bad] + rng.uniform(-3, 3, (bad.sum(), 2))
    tri_p, tri_c = triangulate_stereo(RIG, uv_pl, uv_pr), triangulate_stereo(RIG, uv_cl, uv_cr)
    ok = tri_p.ok & tri_c.ok
    return dict(
        P_prev=tri_p.points[ok],
        P_cur=tri_c.points[ok],
        S_prev=feature_covariance(RIG, uv_pl[ok], uv_pr[ok], S[ok], S[ok]),
        S_cur=feature_covariance(RIG, uv_cl[ok], uv_cr[ok], S[ok], S[ok]),
        uv_l=uv_cl[ok],
        uv_r=uv_cr[ok],
        bad=bad[ok],
    )


def test_ransac_and_ml_recover_known_motion_with_outliers():
    M_true = se3(rpy_to_R(0.0, 0.0, np.radians(3.0)), np.array([0.35, 0.02, 0.0]))
    t = _synthetic_tracks(np.random.default_rng(11), M_true)
    params = VoParams()
    rs = ransac_motion(t["P_prev"], t["P_cur"], t["S_prev"], t["S_cur"], t["uv_l"], t["uv_r"], RIG, params)
    assert rs.n_inliers >= 0.6 * (~t["bad"]).sum()
    assert not (rs.inliers & t["bad"]).sum() > 2  # outliers found out
    idx = np.flatnonzero(rs.inliers)
    ml = ml_refine(t["P_prev"][idx], t["P_cur"][idx], t["S_prev"][idx], t["S_cur"][idx], rs.R, rs.T, params)
    assert ml.converged
    M, cov = motion_from_RT(ml.R, ml.T, ml.covariance)
    dt, dr = motion_error(M, M_true)
    assert dt < 0.01 and dr < 0.2
    # the reported uncertainty is honest to within a factor of a few
    assert np.sqrt(np.trace(cov[:3, :3])) > dt / 5


def test_ml_improves_on_least_squares_start():
    M_true = se3(rpy_to_R(np.radians(1.0), np.radians(-2.0), np.radians(5.0)), np.array([0.3, -0.05, 0.03]))
    t = _synthetic_tracks(np.random.default_rng(12), M_true, outlier_frac=0.0)
    params = VoParams()
    R0 = so3_exp(np.radians([1.0, -1.0, 2.0])) @ se3_inv(M_true)[:3, :3]  # a poor start
    T0 = se3_inv(M_true)[:3, 3] + [0.03, -0.02, 0.01]
    ml = ml_refine(t["P_prev"], t["P_cur"], t["S_prev"], t["S_cur"], R0, T0, params)
    assert ml.converged and ml.iterations < params.ml_max_iterations
    dt, dr = motion_error(motion_from_RT(ml.R, ml.T)[0], M_true)
    assert dt < 0.005 and dr < 0.1


def test_ransac_is_deterministic_for_a_seed():
    M_true = se3(rpy_to_R(0, 0, np.radians(2.0)), np.array([0.2, 0.0, 0.0]))
    t = _synthetic_tracks(np.random.default_rng(13), M_true)
    args = (t["P_prev"], t["P_cur"], t["S_prev"], t["S_cur"], t["uv_l"], t["uv_r"], RIG, VoParams())
    a, b = ransac_motion(*args), ransac_motion(*args)
    np.testing.assert_array_equal(a.inliers, b.inliers)
    np.testing.assert_array_equal(a.T, b.T)


def test_motion_covariance_conversion_matches_numerical_jacobian():
    rng = np.random.default_rng(14)
    R, T = so3_exp(np.radians([2.0, -1.0, 8.0])), np.array([-0.3, 0.05, 0.02])
    A = rng.normal(size=(6, 6))
    cov_RT = A @ A.T * 1e-6
    _, cov_M = motion_from_RT(R, T, cov_RT)
    # numerical: perturb (delta, dT), measure (dt_M, dtheta_M)
    M0, _ = motion_from_RT(R, T)
    J = np.zeros((6, 6))
    h = 1e-7
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        M1, _ = motion_from_RT(so3_exp(d[:3]) @ R, T + d[3:])
        from nav.geometry import so3_log

        J[:3, k] = (M1[:3, 3] - M0[:3, 3]) / h
        J[3:, k] = so3_log(M1[:3, :3] @ M0[:3, :3].T) / h
    np.testing.assert_allclose(cov_M, J @ cov_RT @ J.T, rtol=1e-4, atol=1e-12)


# ---- step 8: sanity constraints --------------------------------------------------------------------------------
def test_sanity_constraints_reject_too_large_update():
    pred = se3(np.eye(3), np.array([0.35, 0.0, 0.0]))
    vo_small = se3(rpy_to_R(0, 0, np.radians(0.5)), np.array([0.30, 0.01, 0.0]))
    vo_large = se3(np.eye(3), np.array([0.05, 0.0, 0.0]))
    c = SanityConstraints(max_update_m=0.1, max_yaw_update_deg=2.0)
    assert sanity_check(vo_small, pred, c) == (True, "")
    ok, why = sanity_check(vo_large, pred, c)
    assert not ok and "magnitude" in why
    ok, why = sanity_check(se3(rpy_to_R(0, 0, np.radians(5)), pred[:3, 3]), pred, c)
    assert not ok and "yaw" in why
    off = SanityConstraints(**{k: None for k in SanityConstraints.__dataclass_fields__ if k.startswith("max_")})
    ok, _ = sanity_check(vo_large, pred, off)  # no limits: anything goes
    assert ok


@pytest.mark.parametrize(
    ("motion", "word"),
    [
        (se3(np.eye(3), np.array([1.5, 0.0, 0.0])), "magnitude"),  # 1.15 m update > 1 m
        (se3(np.eye(3), np.array([0.35, 0.0, 0.0])) @ se3(rpy_to_R(np.radians(8), 0, 0), np.zeros(3)), "roll"),
        (se3(np.eye(3), np.array([0.35, 0.0, 0.0])) @ se3(rpy_to_R(0, np.radians(8), 0), np.zeros(3)), "pitch"),
        (se3(np.eye(3), np.array([0.35, 0.0, 0.0])) @ se3(rpy_to_R(0, 0, np.radians(15)), np.zeros(3)), "yaw"),
    ],
)
def test_default_sanity_constraints_reject_a_crafted_bad_update(motion, word):
    """MER's step-8 constraints are on by default with flight-like limits."""
    pred = se3(np.eye(3), np.array([0.35, 0.0, 0.0]))
    c = SanityConstraints()
    assert sanity_check(pred, pred, c) == (True, "")
    ok, why = sanity_check(motion, pred, c)
    assert not ok and word in why, why


@pytest.mark.parametrize("axis", [0, 1])
def test_default_sanity_constraints_limit_each_site_axis(axis):
    pred = se3(np.eye(3), np.array([0.35, 0.0, 0.0]))
    t = np.array([0.35, 0.0, 0.0])
    t[axis] += 1.05  # an x or y update just over 1 m
    c = SanityConstraints(max_update_m=None)
    ok, why = sanity_check(se3(np.eye(3), t), pred, c, np.eye(3))
    assert not ok and f"update {'XY'[axis]}" in why, why


def test_sanity_downslope_angle_and_site_frame_components():
    # rover facing east across a slope that falls to the south (rolled 15 deg, right side down)
    R_w = rpy_to_R(np.radians(15.0), 0.0, 0.0)
    pred = se3(np.eye(3), np.array([0.35, 0.0, 0.0]))
    slid_down = se3(np.eye(3), np.array([0.35, -0.10, 0.0]))  # rover -y = downslope here
    slid_up = se3(np.eye(3), np.array([0.35, +0.10, 0.0]))
    c = SanityConstraints(max_downslope_angle_deg=45.0)
    assert sanity_check(slid_down, pred, c, R_w)[0]
    ok, why = sanity_check(slid_up, pred, c, R_w)
    assert not ok and "downslope" in why
    ok, why = sanity_check(slid_down, pred, SanityConstraints(max_update_y_m=0.05), R_w)
    assert not ok and "Y" in why
    assert sanity_check(slid_down, pred, SanityConstraints(max_update_x_m=0.05), R_w)[0]


def test_ml_covariance_matches_monte_carlo_spread():
    """Over repeated noise draws, the spread of the ML motion agrees with its reported covariance (factor 2)."""
    M_true = se3(rpy_to_R(0.0, 0.0, np.radians(3.0)), np.array([0.35, 0.0, 0.0]))
    params = VoParams()
    rng = np.random.default_rng(15)
    errs, sig = [], []
    for _ in range(40):
        t = _synthetic_tracks(rng, M_true, n=80, noise_px=0.2, outlier_frac=0.0)
        ti = se3_inv(M_true)
        ml = ml_refine(t["P_prev"], t["P_cur"], t["S_prev"], t["S_cur"], ti[:3, :3], ti[:3, 3], params)
        M, cov = motion_from_RT(ml.R, ml.T, ml.covariance)
        errs.append(M[:3, 3] - M_true[:3, 3])
        sig.append(np.sqrt(np.diag(cov)[:3]))
    spread, predicted = np.std(errs, axis=0), np.mean(sig, axis=0)
    assert np.all(spread < 2.0 * predicted) and np.all(spread > 0.5 * predicted)
