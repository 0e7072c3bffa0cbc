"""The "bring your own VO" example (rover_sim/examples/opencv_vo.py) on the synthetic stereo scenes of
tests/nav/vo_synth.py.

Same scene, rig, motion and (deliberately wrong) dead-reckoning prediction as tests/nav/test_vo_pipeline.py, with the
built-in MER VO run on the same frames for comparison. Tolerances for the example: 1.5 cm and 0.25 deg on a 0.30 m /
3 deg step (5 % of the step); it measures about 5 mm and 0.1 deg here (about 3x margin), the built-in about 1 mm and
0.03 deg (its own test asserts 1 cm / 0.2 deg, asserted here too).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from nav.geometry import rpy_to_R, se3
from nav.protocols import VisualOdometer, check_vo_result
from nav.vo import VisualOdometry
from rover_sim.examples.opencv_vo import OpenCvStereoVO

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "nav"))  # the synthetic scenes of tests/nav
from vo_synth import make_rig, make_terrain, motion_error, render_pair, rover_pose  # noqa: E402

RIG = make_rig()
STEP = se3(rpy_to_R(np.radians(0.5), np.radians(-1.0), np.radians(3.0)), np.array([0.30, 0.03, 0.01]))
PREDICTED = se3(rpy_to_R(0.0, 0.0, np.radians(2.0)), np.array([0.40, 0.0, 0.0]))  # slip + heading error
TURN = se3(rpy_to_R(0.0, 0.0, np.radians(10.0)), np.array([0.05, 0.0, 0.0]))
TURN_PREDICTED = se3(rpy_to_R(0.0, 0.0, np.radians(12.0)), np.zeros(3))
TOL = {OpenCvStereoVO: (0.015, 0.25), VisualOdometry: (0.01, 0.2)}  # (m, deg)


@pytest.fixture(scope="module")
def scene():
    terrain = make_terrain(seed=1)
    T0 = rover_pose(terrain, 0.0, 0.0, 0.0)
    return terrain, T0, render_pair(terrain, RIG, T0, seed=1)


def _run(vo, pair0, pair1, predicted):
    first = vo.step(*pair0, RIG)
    check_vo_result(first)
    assert first.status == "first_frame" and first.motion_rover is None
    res = vo.step(*pair1, RIG, predicted)
    check_vo_result(res)
    return res


def test_is_a_visual_odometer():
    vo = OpenCvStereoVO()
    assert isinstance(vo, VisualOdometer)
    assert isinstance(VisualOdometry(), VisualOdometer)  # the built-in, for comparison


@pytest.mark.parametrize(("motion", "predicted"), [(STEP, PREDICTED), (TURN, TURN_PREDICTED)], ids=["step", "turn"])
def test_recovers_known_motion_like_the_builtin(scene, motion, predicted):
    terrain, T0, pair0 = scene
    pair1 = render_pair(terrain, RIG, T0 @ motion, seed=2)
    results = {}
    for cls in (OpenCvStereoVO, VisualOdometry):
        res = results[cls] = _run(cls(), pair0, pair1, predicted)
        assert res.status == "ok", f"{cls.__name__}: {res.status} {res.reason}"
        dt, dr = motion_error(res.motion_rover, motion)
        print(f"\n{cls.__name__:>15}: error {1000 * dt:.2f} mm, {dr:.3f} deg, {res.n_inliers} inliers")
        max_dt, max_dr = TOL[cls]
        assert dt < max_dt and dr < max_dr, f"{cls.__name__}: {1000 * dt:.1f} mm, {dr:.3f} deg"
    res = results[OpenCvStereoVO]
    assert res.n_inliers >= 40 and res.inliers is not None and res.inliers.sum() == res.n_inliers
    # a 6x6 covariance over (dt, dtheta) of plausible size (sub-mm to cm, well under a degree)
    sig = np.sqrt(np.diag(res.covariance))
    assert np.all(sig[:3] > 1e-5) and np.all(sig[:3] < 0.01) and np.all(np.degrees(sig[3:]) < 0.5)


def test_refuses_textureless_pair(scene):
    _, _, pair0 = scene
    flat = np.full_like(pair0[0], 128)
    vo = OpenCvStereoVO()
    res = _run(vo, (flat, flat), (flat, flat), PREDICTED)
    assert res.status != "ok" and res.motion_rover is None and res.reason
    # textured previous pair, blank current one: nothing can be tracked
    vo.reset()
    res = _run(vo, pair0, (flat, flat), PREDICTED)
    assert res.status != "ok" and res.motion_rover is None and res.reason


def test_reset_forgets_the_previous_pair(scene):
    _, _, pair0 = scene
    vo = OpenCvStereoVO()
    vo.step(*pair0, RIG)
    vo.reset()
    assert vo.step(*pair0, RIG).status == "first_frame"
    res = vo.step(*pair0, RIG, np.eye(4))  # the same pair again: no motion
    check_vo_result(res)
    assert res.status == "ok"
    dt, dr = motion_error(res.motion_rover, np.eye(4))
    assert dt < 0.002 and dr < 0.05
