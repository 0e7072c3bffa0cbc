"""The in-flight epipolar check (nav/epipolar.py): relative pitch and roll from row disparities."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nav.camera import PinholeCamera, StereoRig
from nav.epipolar import (
    MAX_ROTATION_RAD,
    MAX_SCALE,
    MIN_MATCHES,
    ROW_FLOOR_PX,
    EpipolarCheck,
    fit_row_rotation,
    fit_rows,
    matched_corners,
    refine_calibration,
    right_correction,
    row_design,
)
from nav.lens import CahvorCamera
from nav.rectify import StereoCalibration, epipolar_row_error_px, rectification

NAVCAM_R = (0.0, -0.010, 0.003)


def _pose(rotvec_deg, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.radians(rotvec_deg)).as_matrix()
    T[:3, 3] = t
    return T


def _rectified_px(true: CahvorCamera, calib: CahvorCamera, cam: PinholeCamera, p_rover: np.ndarray) -> np.ndarray:
    """Where a rover-frame point lands in a rectified image: the true raw pixel, read through the calibrated
    model into the rectified camera ``cam`` (what the rectification tables do)."""
    raw = true.project((p_rover - true.T_rover_cam[:3, 3]) @ true.T_rover_cam[:3, :3])
    ray = calib.unproject(raw) @ (cam.T_rover_cam[:3, :3].T @ calib.T_rover_cam[:3, :3]).T
    return np.stack([cam.fx_px * ray[:, 0] / ray[:, 2] + cam.cx_px, cam.fy_px * ray[:, 1] / ray[:, 2] + cam.cy_px], 1)


def _navcam_pair(error_deg) -> tuple[CahvorCamera, CahvorCamera, StereoCalibration]:
    """True navcam models 20 cm apart, and a calibration whose right camera is off by ``error_deg`` (its frame)."""
    true_l = CahvorCamera.from_pinhole(PinholeCamera.from_fov("n_left", 256, 256, 45.0), r=NAVCAM_R)
    true_r = replace(true_l, name="n_right", T_rover_cam=_pose([0, 0, 0], [0.2, 0, 0]))
    wrong_r = replace(true_r, T_rover_cam=true_r.T_rover_cam @ _pose(error_deg, [0, 0, 0]))
    return true_l, true_r, StereoCalibration(true_l, wrong_r, true_l.pinhole())


def _matches(true_l, true_r, calib, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rectified (uv_left, uv_right) of ``n`` scene points 2-30 m ahead, with 0.05 px matching noise and 10 %
    gross mismatches (up to 1.5 px), and their true (noise-free) disparities."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(2.0, 30.0, n)
    p = np.stack([rng.uniform(-0.38, 0.38, n) * z, rng.uniform(-0.38, 0.38, n) * z, z], 1)
    rig = rectification(calib).rig
    uv_l = _rectified_px(true_l, calib.left, rig.left, p)
    uv_r = _rectified_px(true_r, calib.right, rig.right, p)
    disparity = uv_l[:, 0] - uv_r[:, 0]
    noisy_r = uv_r + rng.normal(0.0, 0.05, uv_r.shape)
    bad = rng.random(n) < 0.1
    noisy_r[bad, 1] += rng.uniform(-1.5, 1.5, bad.sum())
    return uv_l, noisy_r, disparity


def test_fit_removes_the_relative_pitch_and_roll_and_leaves_the_toe_in() -> None:
    """A right camera off by 0.05 deg in pitch, 0.08 deg in roll and 0.03 deg in toe-in: fitted on one set of
    matches (noise and 10 % mismatches), the corrected calibration's true row error on *other* scene points falls
    from over a quarter pixel to under 0.02 px; the toe-in (not observable in rows) is left as it was."""
    true_l, true_r, calib = _navcam_pair([0.05, 0.03, 0.08])
    uv_l, uv_r, _ = _matches(true_l, true_r, calib, 300, seed=1)
    rect = rectification(calib)
    fit = fit_row_rotation(uv_l, uv_r, rect.rig)
    assert fit.before_px > 0.25 and fit.after_px < 0.06
    refined = refine_calibration(calib, right_correction(calib, rect.rig, fit.rotation_rad))
    held_l, _, held_d = _matches(true_l, true_r, calib, 200, seed=2)  # other points (uncorrected rectification)
    before = epipolar_row_error_px(rect, calib, true_l, true_r, held_l, held_d)
    after = epipolar_row_error_px(rectification(refined), refined, true_l, true_r, held_l, held_d)
    assert np.median(np.abs(before)) > 0.25
    assert np.median(np.abs(after)) < 0.02
    # the remaining relative rotation (camera frame): pitch and roll gone, toe-in as calibrated
    residual = Rotation.from_matrix(true_r.T_rover_cam[:3, :3].T @ refined.right.T_rover_cam[:3, :3]).as_rotvec()
    np.testing.assert_allclose(np.degrees(residual), [0.0, 0.03, 0.0], atol=0.004)


def _textured(seed: int, px: int = 256) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.uniform(0, 255, (px, px)).astype(np.float32), (0, 0), 1.5)
    return cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def _shifted(img: np.ndarray, du: float, dv: float) -> np.ndarray:
    return cv2.warpAffine(img, np.float32([[1, 0, du], [0, 1, dv]]), img.shape[::-1], flags=cv2.INTER_CUBIC,
                          borderMode=cv2.BORDER_REFLECT)  # fmt: skip


def _pinhole_calibration() -> StereoCalibration:
    left = PinholeCamera.from_fov("c_left", 256, 256, 45.0)
    right = replace(left, name="c_right", T_rover_cam=_pose([0, 0, 0], [0.2, 0, 0]))
    return StereoCalibration.from_rig(StereoRig(left, right))


def test_check_pools_pairs_until_it_has_enough_corners_then_aligns_the_rows() -> None:
    """Images whose right rows sit 0.4 px low (a relative pitch): a pair with too few corners is pooled and
    nothing is corrected; the next pair completes the fit, and rectifying with the corrected calibration puts
    matched rows within a tenth of a pixel (0.4 px before)."""
    calib = _pinhole_calibration()
    rect = rectification(calib)
    check = EpipolarCheck()
    left = _textured(0)
    flat = np.full_like(left, 128)
    flat[100:140, 100:140] = left[100:140, 100:140]  # a small textured patch: few corners
    assert not check.observe(calib, rect.rig, flat, _shifted(flat, -6.0, 0.4))
    assert check.correction is None and check.calibration(calib) is calib
    assert check.observe(calib, rect.rig, left, _shifted(left, -6.0, 0.4))
    assert MIN_MATCHES <= check.fit.n_matches and check.fit.before_px == pytest.approx(0.4, abs=0.05)
    assert check.fit.rotation_rad[0] == pytest.approx(-0.4 / rect.rig.right.fy_px, rel=0.15)
    # the raw pair through the corrected calibration: the right image re-sampled 0.4 px up
    fixed = rectification(check.calibration(calib))
    other = _textured(1)
    raw_right = _shifted(other, -6.0, 0.4)
    uv_l, uv_r = matched_corners(*fixed.apply(other, raw_right))
    assert len(uv_l) > 100 and np.median(np.abs(uv_r[:, 1] - uv_l[:, 1])) < 0.1
    assert not check.observe(calib, rect.rig, left, raw_right)  # fitted once: later pairs change nothing


def test_check_refuses_a_correction_too_large_to_be_a_calibration_error() -> None:
    """Rows 5 px apart (about 1 deg at 256^2) are a mismatch or a broken camera, not a calibration residual:
    no correction is made."""
    calib = _pinhole_calibration()
    rect = rectification(calib)
    check = EpipolarCheck()
    left = _textured(3)
    assert 5.0 / rect.rig.right.fy_px > MAX_ROTATION_RAD
    assert not check.observe(calib, rect.rig, left, _shifted(left, -6.0, 5.0))
    assert check.correction is None


def test_check_leaves_pairs_whose_calibration_error_cannot_move_their_rows() -> None:
    """With the calibration's stated sigma (0.02 deg, the flight profile's), a 256^2 navcam-like rig (310 px focal
    length: 0.11 px a sigma) is checked and a 124 deg hazcam-like rig (68 px: 0.024 px, under ROW_FLOOR_PX) is not:
    there a constant 0.1 px resampling offset would be read as a 1.5 mrad pitch, four sigma of the calibration."""
    sigma = np.radians(0.02)
    navcam = _pinhole_calibration()
    hazcam_l = PinholeCamera.from_fov("h_left", 256, 256, 124.0)
    hazcam = StereoCalibration.from_rig(
        StereoRig(hazcam_l, replace(hazcam_l, name="h_right", T_rover_cam=_pose([0, 0, 0], [0.1, 0, 0])))
    )
    left = _textured(4)
    right = _shifted(left, -6.0, 0.1)
    for calib, checked in ((navcam, True), (hazcam, False)):
        rect = rectification(calib)
        check = EpipolarCheck(prior_sigma_rad=sigma)
        assert check.resolvable(rect.rig) is checked
        assert bool(rect.rig.right.fy_px * sigma >= ROW_FLOOR_PX) is checked
        assert check.observe(calib, rect.rig, left, right) is checked
        assert (check.correction is not None) is checked
    assert EpipolarCheck(prior_sigma_rad=0.0).resolvable(rectification(navcam).rig) is False  # nothing to find


def _range_error_frac(true_l, true_r, calib: StereoCalibration, p_rover: np.ndarray) -> np.ndarray:
    """Relative range error of stereo through ``calib``'s rectification for rover-frame points (noise-free)."""
    rig = rectification(calib).rig
    uv_l = _rectified_px(true_l, calib.left, rig.left, p_rover)
    uv_r = _rectified_px(true_r, calib.right, rig.right, p_rover)
    depth = rig.depth_from_disparity(uv_l[:, 0] - uv_r[:, 0])
    true_depth = (p_rover - rig.left.T_rover_cam[:3, 3]) @ rig.left.T_rover_cam[:3, 2]
    return depth / true_depth - 1.0


def test_fit_with_scale_recovers_a_relative_focal_error_and_removes_its_range_error() -> None:
    """A 1024 px navcam pair whose right focal length is calibrated 0.11 % long (and 0.03 deg off in pitch): rows
    show it as a magnification of the right image (-0.11 %), and the corrected calibration's range error at the
    image edges, 20 m out, falls from over 3 % to under 0.3 %. Without the scale term it stays."""
    true_l = CahvorCamera.from_pinhole(PinholeCamera.from_fov("n_left", 1024, 1024, 45.0), r=NAVCAM_R)
    true_r = replace(true_l, name="n_right", T_rover_cam=_pose([0, 0, 0], [0.2, 0, 0]))
    wrong_r = replace(true_r, T_rover_cam=true_r.T_rover_cam @ _pose([0.03, 0, 0], [0, 0, 0]),
                      fx_px=true_r.fx_px * 1.0011, fy_px=true_r.fy_px * 1.0011)  # fmt: skip
    calib = StereoCalibration(true_l, wrong_r, true_l.pinhole())
    uv_l, uv_r, _ = _matches(true_l, true_r, calib, 400, seed=5)
    rect = rectification(calib)
    fits = {}
    for scale in (False, True):
        fits[scale] = fit_rows(row_design(uv_r, rect.rig, scale), uv_r[:, 1] - uv_l[:, 1])
    fit = fits[True]
    assert fit.scale == pytest.approx(-0.0011, abs=0.0001)
    edges = np.array([[x * 20.0, 0.0, 20.0] for x in (-0.38, 0.38)])  # camera frame, at the image's side edges
    p = edges @ true_l.T_rover_cam[:3, :3].T + true_l.T_rover_cam[:3, 3]
    before = _range_error_frac(true_l, true_r, calib, p)
    assert np.max(np.abs(before)) > 0.03
    for scale, bar in ((False, 0.03), (True, 0.003)):
        f = fits[scale]
        refined = refine_calibration(calib, right_correction(calib, rect.rig, f.rotation_rad), f.scale)
        err = np.max(np.abs(_range_error_frac(true_l, true_r, refined, p)))
        assert bool(err < bar) is scale, (scale, err)


def test_check_with_fit_scale_applies_the_focal_correction_and_refuses_a_huge_one() -> None:
    """The check with ``fit_scale``: right rows magnified 0.2 % (a 1024 px rig) are fitted and corrected (the
    right focal length scaled by the fit); a 3 % magnification is no calibration error and is refused."""
    left = PinholeCamera.from_fov("c_left", 1024, 1024, 45.0)
    right = replace(left, name="c_right", T_rover_cam=_pose([0, 0, 0], [0.2, 0, 0]))
    calib = StereoCalibration.from_rig(StereoRig(left, right))
    rect = rectification(calib)
    img = _textured(6, 1024)

    def magnified(k: float) -> np.ndarray:
        c = (1024 - 1) / 2.0
        M = np.float32([[k, 0, c * (1 - k) - 6.0], [0, k, c * (1 - k)]])
        return cv2.warpAffine(img, M, (1024, 1024), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)

    check = EpipolarCheck(fit_scale=True)
    assert check.observe(calib, rect.rig, img, magnified(1.002))
    assert check.scale == pytest.approx(0.002, abs=0.0003)
    assert check.calibration(calib).right.fx_px == pytest.approx(right.fx_px * (1 + check.scale))
    assert abs(check.fit.rotation_rad[0]) < 1e-4
    huge = EpipolarCheck(fit_scale=True)
    assert MAX_SCALE < 0.03 and not huge.observe(calib, rect.rig, img, magnified(1.03)) and huge.correction is None
