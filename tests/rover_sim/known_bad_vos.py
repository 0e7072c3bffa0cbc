"""Known-bad visual odometers: the gate must fail each of them (plugins, loaded by import path in the tests).

Each wraps MER VO (``nav.vo.VisualOdometry``) and adds one defect a real estimator could have:

- :class:`ScaleErrorVO`: every accepted translation 1 % too long (a stereo baseline or focal length error);
- :class:`YawBiasVO`: a heading that drifts 0.05 deg per accepted step, each step's motion reported in that drifting
  frame (rotation and translation). MER's position-only update ignores a VO's rotation, so a bias in the rotation
  alone would be harmless by design; a VO that integrates its own heading turns its translations with it;
- :class:`EchoDeadReckoningVO`: reports the dead-reckoned prediction as its measurement (VO that measures nothing);
- :class:`RefuseAllVO`: refuses every step (VO that never converges).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from nav.vo import VisualOdometry, VoResult

SCALE_ERROR = 0.01
YAW_BIAS_DEG_PER_STEP = 0.05


class _Wrapped:
    def __init__(self, params=None):  # noqa: ANN001 - the scenario's [nav.vo] parameters
        self.vo = VisualOdometry(params) if params is not None else VisualOdometry()

    def reset(self) -> None:
        self.vo.reset()

    def step(self, left_u8, right_u8, rig, predicted_motion_rover=None, R_world_rover=None, feature_mask=None):  # noqa: ANN001, ANN201
        res = self.vo.step(left_u8, right_u8, rig, predicted_motion_rover, R_world_rover, feature_mask)
        if res.status != "ok":
            return res
        return replace(res, motion_rover=self.distort(np.array(res.motion_rover, float)))

    def distort(self, T: np.ndarray) -> np.ndarray:
        return T


class ScaleErrorVO(_Wrapped):
    def distort(self, T: np.ndarray) -> np.ndarray:
        T[:3, 3] *= 1.0 + SCALE_ERROR
        return T


def _rz(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class YawBiasVO(_Wrapped):
    def __init__(self, params=None):  # noqa: ANN001
        super().__init__(params)
        self.steps = 0  # accepted steps since the last reset: the drift so far

    def reset(self) -> None:
        super().reset()
        self.steps = 0

    def distort(self, T: np.ndarray) -> np.ndarray:
        self.steps += 1
        bias = math.radians(YAW_BIAS_DEG_PER_STEP)
        T[:3, :3] = T[:3, :3] @ _rz(bias)
        T[:3, 3] = _rz(bias * self.steps) @ T[:3, 3]
        return T


class EchoDeadReckoningVO(_Wrapped):
    def step(self, left_u8, right_u8, rig, predicted_motion_rover=None, R_world_rover=None, feature_mask=None):  # noqa: ANN001, ANN201
        pred = np.eye(4) if predicted_motion_rover is None else np.asarray(predicted_motion_rover, dtype=float)
        return VoResult("ok", motion_rover=pred, n_inliers=100)


class RefuseAllVO(_Wrapped):
    def step(self, left_u8, right_u8, rig, predicted_motion_rover=None, R_world_rover=None, feature_mask=None):  # noqa: ANN001, ANN201
        return VoResult("too_few_features", reason="refuses every step")


KNOWN_BAD = {
    "scale_1pct": "known_bad_vos:ScaleErrorVO",
    "yaw_bias": "known_bad_vos:YawBiasVO",
    "echo_dead_reckoning": "known_bad_vos:EchoDeadReckoningVO",
    "refuse_all": "known_bad_vos:RefuseAllVO",
}
