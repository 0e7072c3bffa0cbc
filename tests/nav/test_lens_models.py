"""Camera models as flown (nav.lens) and onboard rectification (nav.rectify)."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nav.camera import PinholeCamera, StereoRig
from nav.lens import CahvorCamera, FisheyeCamera, pixel_grid
from nav.rectify import (
    StereoCalibration,
    epipolar_row_error_px,
    rectification,
    rectified_rig,
    rectifying_rotation,
    valid_zoom,
)

NAVCAM_R = (0.0, -0.010, 0.003)  # the flight defaults of [sensors.lens]
HAZCAM_K = (0.01, -0.002, 0.0, 0.0)


def navcam(px: int = 1024) -> CahvorCamera:
    pin = PinholeCamera.from_fov("navcam_left", px, px, 45.0)
    return CahvorCamera.from_pinhole(pin, r=NAVCAM_R, o_cam=(0.003, -0.002, 1.0))


def hazcam(px: int = 1024) -> FisheyeCamera:
    return FisheyeCamera.from_fov("hazcam_front_left", px, px, 124.0, k=HAZCAM_K)


MODELS = {"cahvor_navcam": navcam, "fisheye_hazcam": hazcam}


@pytest.mark.parametrize("name", MODELS)
def test_project_unproject_round_trip_whole_image(name) -> None:
    """Every pixel centre of the 1024^2 image (and the outer edge) -> ray -> pixel within 0.01 px."""
    cam = MODELS[name]()
    uv = pixel_grid(cam.width_px, cam.height_px)
    edge = np.array([[-0.5, -0.5], [cam.width_px - 0.5, cam.height_px - 0.5], [-0.5, 511.5], [511.5, -0.5]])
    uv = np.vstack([uv, edge])
    for depth in (0.3, 7.0):
        back = cam.project(cam.unproject(uv) * depth)
        assert np.abs(back - uv).max() < 0.01, f"{name}: worst round trip {np.abs(back - uv).max():.2e} px"


@pytest.mark.parametrize("name", MODELS)
def test_jacobian_matches_finite_differences(name) -> None:
    cam = MODELS[name]()
    rng = np.random.default_rng(3)
    uv = rng.uniform(0, 1023, (200, 2))
    p = cam.unproject(uv) * rng.uniform(0.5, 20.0, (200, 1))
    eps = 1e-6
    numeric = np.stack([(cam.project(p + eps * e) - cam.project(p - eps * e)) / (2 * eps) for e in np.eye(3)], 2)
    J = cam.jacobian(p)
    assert np.abs(J - numeric).max() < 1e-5 * np.abs(J).max()


def test_fisheye_matches_opencv_fisheye() -> None:
    """Independent implementation: cv2.fisheye.projectPoints uses the same Kannala-Brandt model."""
    cam = hazcam()
    p = cam.unproject(np.random.default_rng(1).uniform(0, 1023, (300, 2))) * 2.0
    K = cam.pinhole().K
    ref, _ = cv2.fisheye.projectPoints(p[None], np.zeros(3), np.zeros(3), K, np.array(cam.k))
    np.testing.assert_allclose(cam.project(p), ref[0], atol=1e-6)


def test_distortion_sizes_as_documented() -> None:
    """Navcam corner barrel distortion about 2 px at 1024^2; the hazcam is within ~2 % of f-theta (124 deg wide)."""
    nav = navcam()
    corner = np.array([[0.0, 0.0]])
    shift = np.linalg.norm(nav.pinhole().project(nav.unproject(corner)) - corner)
    assert 1.0 < shift < 4.0
    haz = hazcam()
    edge_deg = haz.off_axis_deg(np.array([[-0.5, 511.5]]))[0]
    assert edge_deg == pytest.approx(62.0, abs=0.01)
    assert 455 < haz.fx_px < 490  # Maki 2003: 2.1 mrad/px at the centre -> 476 px/rad


def test_cahvor_with_zero_r_is_the_pinhole_and_converts_back() -> None:
    pin = PinholeCamera.from_fov("navcam_left", 256, 256, 45.0, T_rover_cam=np.diag([1.0, -1.0, -1.0, 1.0]))
    cam = CahvorCamera.from_pinhole(pin)
    p = np.random.default_rng(0).normal(0, 1, (50, 3)) + [0, 0, 5]
    np.testing.assert_allclose(cam.project(p), pin.project(p), atol=1e-9)
    assert cam.pinhole() == pin or np.allclose(cam.pinhole().K, pin.K)
    vec = cam.cahvor_vectors()  # CAHV: u = (P - C).H / (P - C).A
    P = np.array([0.3, -0.2, -4.0])
    d = P - vec["C"]
    p_cam = (np.linalg.inv(pin.T_rover_cam) @ np.append(P, 1.0))[:3]
    np.testing.assert_allclose([d @ vec["H"] / (d @ vec["A"]), d @ vec["V"] / (d @ vec["A"])],
                               pin.project(p_cam)[0], atol=1e-9)  # fmt: skip


def _pose(rotvec_deg, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.radians(rotvec_deg)).as_matrix()
    T[:3, 3] = t
    return T


@pytest.mark.parametrize("name", MODELS)
def test_rectification_aligns_rows_of_a_misaligned_pair(name) -> None:
    """Raw cameras turned by 0.3 deg differently: points project to equal rows in the rectified rig, and the
    rectified pixel's table entry is where the raw model sees the point."""
    make = MODELS[name]
    l_model = type(make(256))(
        **{**vars(make(256)), "name": "x_left", "T_rover_cam": _pose([0.3, -0.2, 0.1], [0, 0, 0])}
    )
    r_model = type(make(256))(**{**vars(make(256)), "name": "x_right",
                                 "T_rover_cam": _pose([-0.2, 0.3, -0.3], [0.2, 0.001, -0.002])})  # fmt: skip
    target = PinholeCamera.from_fov("x", 256, 256, 45.0 if name.startswith("cahvor") else 124.0)
    calib = StereoCalibration(l_model, r_model, target)
    rect = rectification(calib)
    assert rectification(calib) is rect  # cached
    rig = rect.rig
    pts = np.random.default_rng(2).uniform([-1, -1, 2], [1, 1, 6], (100, 3))  # left-rectified frame
    T_rl = np.linalg.inv(rig.right.T_rover_cam) @ rig.left.T_rover_cam
    uvl = rig.left.project(pts)
    uvr = rig.right.project(pts @ T_rl[:3, :3].T + T_rl[:3, 3])
    np.testing.assert_allclose(uvl[:, 1], uvr[:, 1], atol=1e-9)
    # table entry == raw model projection of the same world point
    p_rover = pts @ rig.left.T_rover_cam[:3, :3].T + rig.left.T_rover_cam[:3, 3]
    p_raw = (p_rover - l_model.T_rover_cam[:3, 3]) @ l_model.T_rover_cam[:3, :3]
    raw_uv = l_model.project(p_raw)
    iu, iv = np.rint(uvl).astype(int).T
    ok = (iu >= 0) & (iu < 256) & (iv >= 0) & (iv < 256)
    assert ok.sum() > 30
    iu, iv, raw_uv = iu[ok], iv[ok], raw_uv[ok]
    # tables are sampled at integer pixels: compare at the nearest pixel through the model directly
    table = np.stack([rect.left_map[0][iv, iu], rect.left_map[1][iv, iu]], 1)
    ray_at_pixel = rig.left.ray(np.stack([iu, iv], 1).astype(float))
    expect = l_model.project(ray_at_pixel @ (l_model.T_rover_cam[:3, :3].T @ rig.left.T_rover_cam[:3, :3]).T)
    np.testing.assert_allclose(table, expect, atol=2e-3)
    # and the point itself: the raw pixel of the table at the (sub-pixel) rectified position is the raw model's
    frac = uvl[ok] - np.stack([iu, iv], 1)
    su, sv = (iu + frac[:, 0]).astype(np.float32)[None], (iv + frac[:, 1]).astype(np.float32)[None]
    local = np.stack([cv2.remap(m, su, sv, cv2.INTER_LINEAR)[0] for m in rect.left_map], 1)
    assert np.abs(local - raw_uv).max() < 0.05


@pytest.mark.parametrize("name", MODELS)
def test_rectified_view_holds_no_pixel_outside_the_raw_images(name) -> None:
    """A pair turned 0.3 deg apart: the rectified focal length is scaled up just enough that every rectified
    pixel of both cameras samples inside its raw image (no black slivers), and no more (0.1 % less would not)."""
    make = MODELS[name]
    left = type(make(256))(**{**vars(make(256)), "name": "x_left", "T_rover_cam": _pose([0.3, -0.2, 0.1], [0, 0, 0])})
    right = type(make(256))(**{**vars(make(256)), "name": "x_right",
                               "T_rover_cam": _pose([-0.2, 0.3, -0.3], [0.2, 0.001, -0.002])})  # fmt: skip
    target = PinholeCamera.from_fov("x", 256, 256, 45.0 if name.startswith("cahvor") else 124.0)
    calib = StereoCalibration(left, right, target)
    rect = rectification(calib)
    zoom = rect.rig.left.fx_px / target.fx_px
    assert 1.0 < zoom < 1.05 and rect.rig.right.fx_px == rect.rig.left.fx_px
    for table in (rect.left_map, rect.right_map):
        assert min(t.min() for t in table) >= -1e-3 and max(t.max() for t in table) <= 255.0 + 1e-3
    R = rectifying_rotation(left.T_rover_cam, right.T_rover_cam)
    assert valid_zoom(calib, R) == zoom
    tighter = StereoCalibration(left, right, replace(target, fx_px=target.fx_px * zoom * 0.999,
                                                     fy_px=target.fy_px * zoom * 0.999))  # fmt: skip
    assert valid_zoom(tighter, R) > 1.0  # the edge of the slightly wider view falls outside a raw image


def test_epipolar_row_error_is_zero_for_the_true_models_and_the_relative_pitch_otherwise() -> None:
    """Ground-truth row error of a calibration: 0 when the calibrated models are the true ones; a relative pitch
    error of the right camera moves every row by about f * angle."""
    true_l = CahvorCamera.from_pinhole(PinholeCamera.from_fov("n_left", 256, 256, 45.0), r=NAVCAM_R)
    true_r = replace(true_l, name="n_right", T_rover_cam=_pose([0, 0, 0], [0.2, 0, 0]))
    uv = np.random.default_rng(4).uniform(20, 236, (50, 2))
    disparity = np.random.default_rng(5).uniform(5, 40, 50)
    exact = StereoCalibration(true_l, true_r, true_l.pinhole())
    assert np.abs(epipolar_row_error_px(rectification(exact), exact, true_l, true_r, uv, disparity)).max() < 1e-9
    pitch_deg = 0.05
    wrong_r = replace(true_r, T_rover_cam=true_r.T_rover_cam @ _pose([pitch_deg, 0, 0], [0, 0, 0]))
    calib = StereoCalibration(true_l, wrong_r, true_l.pinhole())
    dv = epipolar_row_error_px(rectification(calib), calib, true_l, true_r, uv, disparity)
    f = rectification(calib).rig.left.fy_px
    np.testing.assert_allclose(np.median(np.abs(dv)), f * np.radians(pitch_deg), rtol=0.15)


def test_error_free_calibration_reproduces_the_ideal_rig() -> None:
    pin_l = PinholeCamera.from_fov("navcam_left", 256, 256, 45.0, T_rover_cam=_pose([0, 0, 0], [0, 0.1, 0]))
    pin_r = PinholeCamera.from_fov("navcam_right", 256, 256, 45.0, T_rover_cam=_pose([0, 0, 0], [0.2, 0.1, 0]))
    rig = rectified_rig(StereoCalibration(CahvorCamera.from_pinhole(pin_l), CahvorCamera.from_pinhole(pin_r), pin_l))
    ideal = StereoRig(pin_l, pin_r)
    np.testing.assert_allclose(rig.left.T_rover_cam, ideal.left.T_rover_cam, atol=1e-12)
    np.testing.assert_allclose(rig.right.T_rover_cam, ideal.right.T_rover_cam, atol=1e-12)
    np.testing.assert_allclose(rig.left.K, ideal.left.K)
    back = rectified_rig(StereoCalibration.from_rig(ideal))  # StereoRig -> models -> StereoRig
    np.testing.assert_allclose(back.right.T_rover_cam, ideal.right.T_rover_cam, atol=1e-12)
    assert back.baseline_m == pytest.approx(0.2)
