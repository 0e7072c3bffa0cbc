"""Known-bad visual odometers: the gate must fail each of them (plugins, loaded by import path in the tests).

Each wraps MER VO (``nav.vo.VisualOdometry``) and adds one defect a real estimator could have:

- :class:`ScaleErrorVO`: every accepted translation 1 % too long (a stereo baseline or focal length error);
- :class:`YawBiasVO`: every accepted step turned 0.05 deg further left (a gyro-like heading bias per step);
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


class YawBiasVO(_Wrapped):
    def distort(self, T: np.ndarray) -> np.ndarray:
        a = math.radians(YAW_BIAS_DEG_PER_STEP)
        Rz = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
        T[:3, :3] = T[:3, :3] @ Rz
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
