"""PoseSeries: the evaluator's compact pose history reads back exactly what was appended."""

from __future__ import annotations

import numpy as np
import pytest

from nav.trajectory import Pose, Trajectory
from rover_sim.runtime.evaluator import final_slip, window_slips
from rover_sim.runtime.pose_series import PoseSeries


def _poses(n: int, seed: int = 0) -> list[Pose]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        q = rng.normal(size=4)
        out.append(Pose(0.125 * k + rng.random() * 1e-3, rng.normal(size=3) * 100.0, q / np.linalg.norm(q)))
    return out


def test_series_reads_back_every_pose_exactly_across_growth():
    poses = _poses(1000)
    s = PoseSeries(capacity=4)  # grows eight times
    for p in poses:
        s.append(p)
    assert len(s) == 1000 and s
    for k in (0, 1, 3, 4, 5, 511, 512, 999, -1, -1000):
        got, want = s[k], poses[k]
        assert got.t_s == want.t_s
        assert np.array_equal(got.position_xyz_m, want.position_xyz_m)
        assert np.array_equal(got.quat_wxyz, want.quat_wxyz)
    assert np.array_equal(s.positions_xyz_m, np.array([p.position_xyz_m for p in poses]))
    a, b = s.trajectory(), Trajectory.from_poses(poses)
    assert np.array_equal(a.t_s, b.t_s) and np.array_equal(a.positions_xyz, b.positions_xyz)
    assert np.array_equal(a.orientations_quat_wxyz, b.orientations_quat_wxyz)
    assert [p.t_s for p in s] == [p.t_s for p in poses]


def test_series_copies_and_rejects_bad_indices():
    s = PoseSeries()
    assert not s and len(s) == 0
    p = _poses(1)[0]
    s.append(p)
    p.position_xyz_m[:] = 0.0  # the caller reuses its array: the series kept the value
    assert not np.array_equal(s[0].position_xyz_m, p.position_xyz_m)
    s[0].position_xyz_m[:] = 7.0  # a read pose is a copy
    assert not np.all(s[0].position_xyz_m == 7.0)
    with pytest.raises(IndexError, match="pose 1 of a series of 1"):
        s[1]
    with pytest.raises(IndexError):
        s[-2]
    with pytest.raises(TypeError, match="int"):
        s[0:1]


def test_slip_windows_are_the_same_on_a_series_and_a_list():
    poses = _poses(200, seed=1)
    commanded = list(np.cumsum(np.full(200, 0.01)))
    s = PoseSeries()
    for p in poses:
        s.append(p)
    assert np.array_equal(window_slips(s, commanded, 0.3), window_slips(poses, commanded, 0.3))
    assert final_slip(s, commanded) == final_slip(poses, commanded)
