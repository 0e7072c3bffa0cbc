"""Trajectory container, TUM IO, timestamp association and odometry metrics."""

from __future__ import annotations

import numpy as np
import pytest

from nav.geometry import R_to_quat_wxyz, rpy_to_R
from nav.trajectory import (
    Pose,
    Trajectory,
    align_first_pose,
    associate,
    final_position_error_pct,
    interpolate,
    read_tum,
    relative_errors,
    step_slip,
    write_tum,
)


def _straight(n: int = 201, step_m: float = 0.05, scale: float = 1.0, yaw_per_m: float = 0.0) -> Trajectory:
    """Path along +x (or an arc of curvature yaw_per_m), poses every step_m (times scale for a drifting copy)."""
    s = np.arange(n) * step_m * scale
    if yaw_per_m == 0.0:
        xy = np.stack([s, np.zeros(n)], axis=1)
    else:
        xy = np.stack([np.sin(yaw_per_m * s) / yaw_per_m, (1 - np.cos(yaw_per_m * s)) / yaw_per_m], axis=1)
    q = np.array([R_to_quat_wxyz(rpy_to_R(0.0, 0.0, yaw_per_m * si)) for si in s])
    return Trajectory(np.arange(n) * 1.0, np.column_stack([xy, np.zeros(n)]), q)


def test_tum_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    n = 50
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    traj = Trajectory(np.sort(rng.uniform(0, 100, n)), rng.normal(size=(n, 3)), q)
    write_tum(traj, tmp_path / "t.tum")
    first = (tmp_path / "t.tum").read_text().splitlines()[1].split()
    assert len(first) == 8
    assert float(first[7]) == pytest.approx(traj.orientations_quat_wxyz[0, 0], abs=1e-9)  # qw last
    back = read_tum(tmp_path / "t.tum")
    np.testing.assert_allclose(back.t_s, traj.t_s, atol=1e-9)
    np.testing.assert_allclose(back.positions_xyz, traj.positions_xyz, atol=1e-9)
    np.testing.assert_allclose(back.orientations_quat_wxyz, traj.orientations_quat_wxyz, atol=1e-9)


def test_read_tum_rejects_wrong_columns(tmp_path):
    (tmp_path / "bad.txt").write_text("0 1 2 3\n")
    with pytest.raises(ValueError, match="8 columns"):
        read_tum(tmp_path / "bad.txt")


def test_trajectory_from_poses_and_matrices():
    poses = [Pose(float(k), np.array([k, 2.0 * k, 0.0]), R_to_quat_wxyz(rpy_to_R(0, 0, 0.1 * k))) for k in range(5)]
    traj = Trajectory.from_poses(poses)
    assert len(traj) == 5 and traj.path_length_m() == pytest.approx(4 * np.sqrt(5))
    back = Trajectory.from_matrices(traj.t_s, traj.matrices())
    np.testing.assert_allclose(back.matrices(), traj.matrices(), atol=1e-12)
    np.testing.assert_allclose(traj.pose(3).as_matrix(), traj.matrices()[3])


def test_kitti_metric_on_scale_drift():
    ref = _straight()
    est = _straight(scale=1.02)  # odometry over-reads by 2 %
    for seg in relative_errors(est, ref, [1.0, 2.0, 5.0]):
        assert seg.n_segments > 0
        assert seg.translation_error_pct == pytest.approx(2.0, rel=1e-6)
        assert seg.rotation_error_deg_per_m == pytest.approx(0.0, abs=1e-9)
    assert np.isnan(relative_errors(est, ref, [50.0])[0].translation_error_pct)  # longer than the path


def test_kitti_metric_on_heading_drift():
    k = np.radians(2.0)  # estimate turns 2 deg per metre while the reference drives straight
    ref, est = _straight(), _straight(yaw_per_m=k)
    for L in (1.0, 4.0):
        seg = relative_errors(est, ref, [L])[0]
        gap = np.hypot(L - np.sin(k * L) / k, (1 - np.cos(k * L)) / k)
        assert seg.translation_error_pct == pytest.approx(100 * gap / L, rel=1e-6)
        assert seg.rotation_error_deg_per_m == pytest.approx(2.0, rel=1e-6)


def test_final_position_error_pct():
    ref = _straight()  # 10 m
    est = Trajectory(
        ref.t_s, ref.positions_xyz + np.linspace(0, 1, len(ref))[:, None] * [0, 0.1, 0], ref.orientations_quat_wxyz
    )
    assert final_position_error_pct(est, ref) == pytest.approx(1.0)
    # a rigid offset of the whole estimate disappears with first-pose alignment
    shifted = Trajectory(ref.t_s, ref.positions_xyz + [5.0, -3.0, 1.0], ref.orientations_quat_wxyz)
    assert final_position_error_pct(shifted, ref, align_first=True) == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="associate"):
        final_position_error_pct(est[:10], ref)


def test_align_first_pose_rotates_the_whole_estimate():
    ref = _straight()
    T = np.eye(4)
    T[:3, :3] = rpy_to_R(0, 0, 0.5)
    T[:3, 3] = [1, 2, 3]
    moved = ref.transformed(T)
    np.testing.assert_allclose(align_first_pose(moved, ref).matrices(), ref.matrices(), atol=1e-9)


def test_association_nearest_and_interpolated():
    ref = _straight(n=101, step_m=0.1)  # t = 0..100 s, x = 0.1 t
    est = Trajectory(np.array([0.004, 10.5, 20.001, 150.0]), np.zeros((4, 3)), np.tile([1.0, 0, 0, 0], (4, 1)))
    e, r = associate(est, ref, max_dt_s=0.01)
    np.testing.assert_allclose(e.t_s, [0.004, 20.001])
    np.testing.assert_allclose(r.t_s, [0.0, 20.0])
    e, r = associate(est, ref, method="interpolate")
    np.testing.assert_allclose(r.positions_xyz[:, 0], 0.1 * e.t_s, atol=1e-12)
    assert len(e) == 3  # 150 s is outside the reference


def test_interpolation_slerps_orientation():
    q0, q1 = R_to_quat_wxyz(rpy_to_R(0, 0, 0.0)), R_to_quat_wxyz(rpy_to_R(0, 0, 1.0))
    traj = Trajectory([0.0, 2.0], [[0, 0, 0], [2, 0, 0]], [q0, q1])
    mid = interpolate(traj, [0.5])
    np.testing.assert_allclose(mid.positions_xyz[0], [0.5, 0, 0])
    np.testing.assert_allclose(mid.orientations_quat_wxyz[0], R_to_quat_wxyz(rpy_to_R(0, 0, 0.25)), atol=1e-12)
    with pytest.raises(ValueError):
        interpolate(traj, [3.0])


def test_step_slip():
    # the reference makes 0.20, 0.35, 0 and -0.0875 m good along its heading in four 0.35 m commanded steps
    x = np.cumsum([0.0, 0.20, 0.35, 0.0, -0.0875])
    ref = Trajectory(np.arange(5.0), np.column_stack([x, np.zeros(5), np.zeros(5)]), np.tile([1.0, 0, 0, 0], (5, 1)))
    slip = step_slip(ref, np.full(4, 0.35))
    np.testing.assert_allclose(slip, [1 - 0.2 / 0.35, 0.0, 1.0, 1.25], atol=1e-12)  # 125 %: slid back (Spirit, Sol 206)
    np.testing.assert_allclose(step_slip(ref, [0.35 * 4], indices=[0, 4]), [1 - 0.4625 / 1.4])
    with pytest.raises(ValueError):
        step_slip(ref, [0.35])
