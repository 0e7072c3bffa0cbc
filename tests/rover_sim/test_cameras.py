"""Camera models exported from the MJCF: intrinsics, extrinsics (incl. the mast), rectification, JSON (no GL)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import rover_sim  # noqa: F401
from nav.camera import StereoRig
from rover_sim.render.cameras import (
    STEREO_PAIRS,
    StereoRigNotRectified,
    camera_model,
    check_rectified,
    load_rig,
    save_rig,
    stereo_rig,
)
from rover_sim.sim.sensors import point_mast

BASELINES_M = {"navcam": 0.20, "hazcam_front": 0.10, "hazcam_rear": 0.10}  # REFERENCE.md section 1
FOVY_DEG = {"navcam": 45.0, "hazcam_front": 124.0, "hazcam_rear": 124.0}


@pytest.mark.parametrize("pair", STEREO_PAIRS)
def test_camera_stereo_baseline_and_intrinsics(sensor_slope_sim, pair: str) -> None:
    sim = sensor_slope_sim
    rig = stereo_rig(sim.model, sim.data, pair, 256)
    assert rig.baseline_m == pytest.approx(BASELINES_M[pair], abs=1e-9)
    f = 128.0 / math.tan(math.radians(FOVY_DEG[pair]) / 2.0)
    for cam in (rig.left, rig.right):
        assert (cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px) == pytest.approx((f, f, 127.5, 127.5))
    # 1024 native and 256 binned describe the same camera
    big = stereo_rig(sim.model, sim.data, pair, 1024).scaled(0.25)
    np.testing.assert_allclose(big.left.K, rig.left.K, atol=1e-9)


@pytest.mark.parametrize("pan_tilt", [(0.0, 0.0), (0.25, 0.55), (-1.0, -0.3)])
def test_camera_rigs_rectified_at_mast_poses(sensor_slope_sim, pan_tilt) -> None:
    sim = sensor_slope_sim
    point_mast(sim, *pan_tilt, settle_s=1.5)
    try:
        for pair in STEREO_PAIRS:
            rig = stereo_rig(sim.model, sim.data, pair)
            T_lr = np.linalg.inv(rig.left.T_rover_cam) @ rig.right.T_rover_cam
            np.testing.assert_allclose(T_lr[:3, :3], np.eye(3), atol=1e-9)
            np.testing.assert_allclose(T_lr[:3, 3], [BASELINES_M[pair], 0.0, 0.0], atol=1e-9)
    finally:
        point_mast(sim, 0.0, 0.0, settle_s=1.5)


def test_camera_navcam_extrinsics_follow_the_mast(sensor_slope_sim) -> None:
    """OpenCV axes: z is the optical axis; pan about rover +z, positive tilt looks down."""
    sim = sensor_slope_sim
    pan, tilt = point_mast(sim, 0.4, 0.6, settle_s=2.0)
    try:
        T = camera_model(sim.model, sim.data, "navcam_left", 256, 256).T_rover_cam
        expected_axis = [math.cos(tilt) * math.cos(pan), math.cos(tilt) * math.sin(pan), -math.sin(tilt)]
        np.testing.assert_allclose(T[:3, 2], expected_axis, atol=1e-6)
        np.testing.assert_allclose(T[:3, 0], [math.sin(pan), -math.cos(pan), 0.0], atol=1e-6)  # x: image right
        assert T[2, 1] < 0.0  # image down (y) points down in the rover frame
        # mast head 0.975 m above the body origin (1.5 m above ground); the cameras sit 5.5 cm ahead of the tilt axis
        assert T[2, 3] == pytest.approx(0.975 - 0.055 * math.sin(tilt), abs=1e-6)
    finally:
        point_mast(sim, 0.0, 0.0, settle_s=1.5)


def test_camera_hazcams_look_down_and_out(sensor_slope_sim) -> None:
    sim = sensor_slope_sim
    front = camera_model(sim.model, sim.data, "hazcam_front_left", 256, 256).T_rover_cam
    rear = camera_model(sim.model, sim.data, "hazcam_rear_left", 256, 256).T_rover_cam
    s = math.sqrt(0.5)
    np.testing.assert_allclose(front[:3, 2], [s, 0.0, -s], atol=1e-9)  # 45 deg down, forward
    np.testing.assert_allclose(rear[:3, 2], [-s, 0.0, -s], atol=1e-9)  # 45 deg down, backward


def test_camera_non_rectified_pair_is_rejected(sensor_slope_sim) -> None:
    sim = sensor_slope_sim
    rig = stereo_rig(sim.model, sim.data, "navcam")
    T = rig.right.T_rover_cam.copy()
    c, s = math.cos(0.01), math.sin(0.01)
    T[:3, :3] = T[:3, :3] @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # 0.6 deg toe-in
    with pytest.raises(StereoRigNotRectified):
        check_rectified(rig.left, type(rig.right)(**{**rig.right.__dict__, "T_rover_cam": T}))
    T = rig.right.T_rover_cam.copy()
    T[:3, 3] += T[:3, 1] * 0.002  # 2 mm vertical offset
    with pytest.raises(StereoRigNotRectified):
        check_rectified(rig.left, type(rig.right)(**{**rig.right.__dict__, "T_rover_cam": T}))
    with pytest.raises(ValueError, match="unknown stereo pair"):
        stereo_rig(sim.model, sim.data, "pancam")


def test_camera_model_json_round_trip(sensor_slope_sim, tmp_path) -> None:
    sim = sensor_slope_sim
    rig = stereo_rig(sim.model, sim.data, "hazcam_rear", 256)
    path = tmp_path / "camera_model.json"
    save_rig(rig, path)
    back = load_rig(path)
    assert isinstance(back, StereoRig) and back.name == "hazcam_rear"
    for a, b in ((rig.left, back.left), (rig.right, back.right)):
        np.testing.assert_allclose(a.K, b.K)
        np.testing.assert_allclose(a.T_rover_cam, b.T_rover_cam)
    assert back.baseline_m == pytest.approx(0.10)
