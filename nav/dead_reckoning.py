"""MER-style dead reckoning: IMU attitude plus wheel odometry, updated at about 8 Hz (REFERENCE section 3.1).

* :class:`AttitudeEstimator` integrates the gyro rates (body frame) into the attitude quaternion; at rest, roll and
  pitch come from the accelerometers (the average specific force points opposite to gravity). Yaw is only
  propagated (the onboard heading came from sun finding at the start of a drive: pass it as the initial pose).
  Planet rotation and gyro bias estimation are not modelled; a known bias can be given.
* :class:`WheelOdometry` turns encoder increments into a planar body motion. Each wheel rolls ``r * d(angle)``
  along its heading (steering angle for corner wheels, straight ahead for the middle wheels) and does not skid
  sideways; the body twist ``(dx, dy, dyaw)`` that best satisfies the twelve conditions (least squares) covers
  straight drives, arcs and turns in place alike (with all steering at zero it is the differential-drive model).
* :class:`DeadReckoner` composes them: the odometry displacement, in the rover frame, is rotated into the world by
  the IMU attitude at the middle of the interval. On a slope the body x axis is tilted, so the position changes
  in z as well; slip is, by construction, invisible (hence VO).

VO interface (paper section 1: VO corrects the onboard estimate at each stereo pair). When a stereo pair is taken
call :meth:`DeadReckoner.predicted_motion_rover` for VO's prediction (dead-reckoned motion since the previous
pair), then :meth:`DeadReckoner.apply_vo_correction` with VO's motion (or None if VO failed). The pose at the
previous pair is kept; the dead-reckoned increment since then is replaced by the VO motion, the corrected pose
becomes the new reference pair, and dead reckoning continues from it. As on Mars, by default only position is
corrected (the IMU keeps attitude well).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nav.geometry import R_to_quat_wxyz, R_to_rpy, quat_wxyz_to_R, rpy_to_R, se3_inv
from nav.trajectory import Pose, slerp_quat_wxyz
from nav.types import STEERED, WHEELS, EncoderSample, ImuSample, RoverGeometry

__all__ = [
    "AttitudeEstimator",
    "DeadReckoner",
    "OdometryIncrement",
    "Pose",
    "WheelOdometry",
    "apply_vo_correction",
    "roll_pitch_from_accel",
]


# ----------------------------------------------------------------------------------------------------------------
# Attitude
# ----------------------------------------------------------------------------------------------------------------
def roll_pitch_from_accel(accel_m_s2: np.ndarray) -> tuple[float, float]:
    """(roll, pitch) rad of a vehicle at rest from its mean specific force (body frame, ``R^T (0, 0, g)``)."""
    f = np.asarray(accel_m_s2, dtype=float).reshape(-1, 3).mean(axis=0)
    return float(np.arctan2(f[1], f[2])), float(np.arctan2(-f[0], np.hypot(f[1], f[2])))


class AttitudeEstimator:
    """Gyro-integrated attitude (quat_wxyz, rover -> world), levelled from the accelerometers at rest."""

    def __init__(self, quat_wxyz: np.ndarray | None = None, gyro_bias_rad_s: np.ndarray | None = None) -> None:
        self.quat_wxyz = np.array([1.0, 0.0, 0.0, 0.0]) if quat_wxyz is None else _qnorm(np.asarray(quat_wxyz, float))
        self.gyro_bias_rad_s = np.zeros(3) if gyro_bias_rad_s is None else np.asarray(gyro_bias_rad_s, dtype=float)
        self._last: ImuSample | None = None

    @property
    def R_world_rover(self) -> np.ndarray:
        return quat_wxyz_to_R(self.quat_wxyz)

    def level(self, imu_samples: Sequence[ImuSample], yaw_rad: float | None = None) -> None:
        """Set roll and pitch from the mean specific force of samples taken at rest; keep (or set) yaw."""
        roll, pitch = roll_pitch_from_accel(np.array([s.accel_m_s2 for s in imu_samples]))
        yaw = float(R_to_rpy(self.R_world_rover)[2]) if yaw_rad is None else float(yaw_rad)
        self.quat_wxyz = R_to_quat_wxyz(rpy_to_R(roll, pitch, yaw))

    def propagate(self, imu_samples: Sequence[ImuSample]) -> None:
        """Integrate body rates: ``q <- q (x) exp(w dt / 2)`` with the trapezoidal mean rate of consecutive samples."""
        # plain floats: numpy's per-call overhead on 3- and 4-vectors was most of the cost (the same arithmetic,
        # operation for operation, as the array form _qnorm(_qmul(q, _qexp(w dt))))
        q = None
        bx, by, bz = np.asarray(self.gyro_bias_rad_s, dtype=float).tolist()
        last = self._last
        for s in imu_samples:
            if last is not None and s.t_s > last.t_s:
                if q is None:
                    q = tuple(np.asarray(self.quat_wxyz, dtype=float).tolist())
                g1, g0 = s.gyro_rad_s, last.gyro_rad_s
                dt = s.t_s - last.t_s
                w = (0.5 * (float(g1[0]) + float(g0[0])) - bx, 0.5 * (float(g1[1]) + float(g0[1])) - by,
                     0.5 * (float(g1[2]) + float(g0[2])) - bz)  # fmt: skip
                q = _fqnorm(_fqmul(q, _fqexp((w[0] * dt, w[1] * dt, w[2] * dt))))
            last = s
        self._last = last
        if q is not None:
            self.quat_wxyz = np.array(q)

    def set_attitude(self, quat_wxyz: np.ndarray) -> None:
        self.quat_wxyz = _qnorm(np.asarray(quat_wxyz, dtype=float))


# ----------------------------------------------------------------------------------------------------------------
# Wheel odometry
# ----------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class OdometryIncrement:
    """Planar body motion between two encoder samples, in the rover frame at the first sample."""

    dx_m: float
    dy_m: float
    dyaw_rad: float
    distance_m: float  # signed path length of the rover-frame origin the wheels imply ("commanded" distance)
    wheel_distance_m: np.ndarray  # (6,) WHEELS order
    residual_m: float  # RMS misfit of the rolling/no-skid conditions (large: wheels disagree, e.g. one dragging)


class WheelOdometry:
    """Encoder increments -> body motion, by least squares over the wheels' rolling and no-skid conditions."""

    def __init__(self, geometry: RoverGeometry | None = None, lateral_weight: float = 0.1) -> None:
        self.geometry = geometry or RoverGeometry()
        # weight of the no-skid (lateral) conditions relative to the rolling ones: when they conflict (skid
        # steering with unsteered corner wheels, a dragged wheel) the wheels slide sideways more readily than they
        # slip along their rolling direction
        self.lateral_weight = lateral_weight
        self._memo: tuple[EncoderSample, EncoderSample, OdometryIncrement] | None = None

    def increment(self, prev: EncoderSample, cur: EncoderSample) -> OdometryIncrement:
        """Body motion between encoder samples ``prev`` and ``cur`` (the last pair's result is kept: estimators
        that share this odometry and see the same samples solve it once)."""
        memo = self._memo
        if memo is not None and memo[0] is prev and memo[1] is cur:
            return memo[2]
        inc = self._solve(prev, cur)
        self._memo = (prev, cur, inc)
        return inc

    def _solve(self, prev: EncoderSample, cur: EncoderSample) -> OdometryIncrement:
        g = self.geometry
        s = g.wheel_radius_m * (np.asarray(cur.wheel_angle_rad) - np.asarray(prev.wheel_angle_rad))
        steer = np.zeros(len(WHEELS))
        mean_steer = 0.5 * (np.asarray(prev.steer_angle_rad) + np.asarray(cur.steer_angle_rad))
        for k, name in enumerate(STEERED):
            steer[WHEELS.index(name)] = mean_steer[k]
        x, y = g.wheel_xy_m[:, 0], g.wheel_xy_m[:, 1]
        c, sn = np.cos(steer), np.sin(steer)
        # contact-point velocity (a - w y, b + w x): along the heading = s, across it = 0
        A = np.concatenate(
            [np.stack([c, sn, -c * y + sn * x], axis=1), np.stack([-sn, c, sn * y + c * x], axis=1)], axis=0
        )
        rhs = np.concatenate([s, np.zeros_like(s)])
        wts = np.concatenate([np.ones_like(s), np.full_like(s, self.lateral_weight)])
        sol, *_ = np.linalg.lstsq(A * wts[:, None], rhs * wts, rcond=None)
        a, b, w = (float(v) for v in sol)
        res = float(np.sqrt(np.mean((A @ sol - rhs) ** 2)))
        path = float(np.copysign(np.hypot(a, b), a))
        # constant twist over the interval: the chord in the start frame
        if abs(w) > 1e-9:
            V = np.array([[np.sin(w), -(1 - np.cos(w))], [1 - np.cos(w), np.sin(w)]]) / w
            a, b = V @ np.array([a, b])
        return OdometryIncrement(a, b, w, path, s, res)


# ----------------------------------------------------------------------------------------------------------------
# Dead reckoning
# ----------------------------------------------------------------------------------------------------------------
class DeadReckoner:
    """6-DOF pose from IMU attitude and wheel odometry; call :meth:`update` at the encoder rate (~8 Hz)."""

    def __init__(
        self,
        geometry: RoverGeometry | None = None,
        initial_pose: Pose | None = None,
        gyro_bias_rad_s: np.ndarray | None = None,
        level_at_rest: bool = True,
        rest_gyro_rad_s: float = np.radians(0.05),
        rest_accel_tol_m_s2: float = 0.02,
        odometry: WheelOdometry | None = None,
    ) -> None:
        pose = initial_pose or Pose.identity()
        self.odometry = odometry or WheelOdometry(geometry)  # may be shared with another estimator (same wheels)
        self.attitude = AttitudeEstimator(pose.quat_wxyz, gyro_bias_rad_s)
        self.level_at_rest = level_at_rest
        self.rest_gyro_rad_s = rest_gyro_rad_s
        self.rest_accel_tol_m_s2 = rest_accel_tol_m_s2
        self._position = np.array(pose.position_xyz_m, dtype=float)
        self._t_s = pose.t_s
        self._last_encoder: EncoderSample | None = None
        self._vo_frame_pose = self.pose
        self.distance_m = 0.0  # total signed path length according to the wheels

    @property
    def pose(self) -> Pose:
        return Pose(self._t_s, self._position.copy(), self.attitude.quat_wxyz.copy())

    def initialise_at_rest(self, imu_samples: Sequence[ImuSample], heading_rad: float | None = None) -> Pose:
        """Level roll/pitch from accelerometers (rover at rest); heading as given (else kept)."""
        self.attitude.level(imu_samples, heading_rad)
        self.attitude.propagate(imu_samples[-1:])  # start gyro integration at the last sample
        self._vo_frame_pose = self.pose
        return self.pose

    def update(self, imu_samples: Sequence[ImuSample], encoder: EncoderSample) -> Pose:
        """Propagate with the IMU samples since the last call and the new encoder reading; return the new pose."""
        q0 = self.attitude.quat_wxyz.copy()
        self.attitude.propagate(imu_samples)
        if self._last_encoder is None:
            self._last_encoder = encoder
            self._t_s = encoder.t_s
            return self.pose
        inc = self.odometry.increment(self._last_encoder, encoder)
        self._last_encoder = encoder
        if self.level_at_rest and self._at_rest(imu_samples, inc):
            self.attitude.level(imu_samples)
        q1 = self.attitude.quat_wxyz
        R_mid = quat_wxyz_to_R(slerp_quat_wxyz(q0, q1, 0.5))
        self._position = self._position + R_mid @ np.array([inc.dx_m, inc.dy_m, 0.0])
        self.distance_m += inc.distance_m
        self._t_s = encoder.t_s
        return self.pose

    def _at_rest(self, imu_samples: Sequence[ImuSample], inc: OdometryIncrement) -> bool:
        if len(imu_samples) == 0 or np.max(np.abs(inc.wheel_distance_m)) > 1e-6:
            return False
        gyro = np.array([s.gyro_rad_s for s in imu_samples])
        acc = np.array([s.accel_m_s2 for s in imu_samples])
        g = np.linalg.norm(acc.mean(axis=0))
        return bool(
            np.max(np.linalg.norm(gyro, axis=1)) < self.rest_gyro_rad_s
            and np.max(np.abs(np.linalg.norm(acc, axis=1) - g)) < self.rest_accel_tol_m_s2
        )

    # --- VO interface ------------------------------------------------------------------------------------------
    @property
    def vo_frame_pose(self) -> Pose:
        """Pose at the previous stereo pair (the reference of the next VO step)."""
        return self._vo_frame_pose

    def predicted_motion_rover(self) -> np.ndarray:
        """Dead-reckoned motion since the previous stereo pair: 4x4 pose of the current rover frame in that one."""
        return se3_inv(self._vo_frame_pose.as_matrix()) @ self.pose.as_matrix()

    def apply_vo_correction(self, vo_motion_rover: np.ndarray | None, update_attitude: bool = False) -> Pose:
        """Take a stereo pair now: replace the dead-reckoned increment since the previous pair by VO's motion.

        ``vo_motion_rover`` None (VO failed): the dead-reckoned pose stands. Either way the current pose becomes
        the reference for the next VO step. See :func:`apply_vo_correction`.
        """
        if vo_motion_rover is not None:
            new = apply_vo_correction(self._vo_frame_pose, vo_motion_rover, self.pose, update_attitude)
            self._position = new.position_xyz_m.copy()
            self.attitude.set_attitude(new.quat_wxyz)
        self._vo_frame_pose = self.pose
        return self.pose

    def mark_vo_frame(self) -> Pose:
        """Make the current pose the reference of the next VO step without a correction (first pair, re-init)."""
        return self.apply_vo_correction(None)


def apply_vo_correction(
    pose_at_prev_frame: Pose, vo_motion_rover: np.ndarray, current_pose: Pose, update_attitude: bool = False
) -> Pose:
    """Corrected pose at the current stereo pair: ``T_world_prev @ vo_motion`` for position.

    With ``update_attitude`` False (MER practice) the attitude stays the IMU's (``current_pose``), and only the
    position is replaced: ``p = p_prev + R_world_prev @ t_vo``. With True the full VO pose is used.
    """
    T = pose_at_prev_frame.as_matrix() @ np.asarray(vo_motion_rover, dtype=float)
    q = R_to_quat_wxyz(T[:3, :3]) if update_attitude else np.asarray(current_pose.quat_wxyz, dtype=float)
    return Pose(current_pose.t_s, T[:3, 3].copy(), q)


# ----------------------------------------------------------------------------------------------------------------
def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def _qexp(rotvec: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(rotvec))
    if th < 1e-12:
        return _qnorm(np.array([1.0, *(0.5 * np.asarray(rotvec))]))
    return np.array([np.cos(th / 2), *(np.sin(th / 2) * np.asarray(rotvec) / th)])


def _qnorm(q: np.ndarray) -> np.ndarray:
    q = q / np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def _fqmul(a: tuple, b: tuple) -> tuple:
    """:func:`_qmul` on float 4-tuples."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return (
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    )


def _fqexp(r: tuple) -> tuple:
    """:func:`_qexp` on a float 3-tuple."""
    x, y, z = r
    th = math.sqrt(x * x + y * y + z * z)
    if th < 1e-12:
        return _fqnorm((1.0, 0.5 * x, 0.5 * y, 0.5 * z))
    s = math.sin(th / 2)
    return (math.cos(th / 2), s * x / th, s * y / th, s * z / th)


def _fqnorm(q: tuple) -> tuple:
    """:func:`_qnorm` on a float 4-tuple."""
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return (w, x, y, z) if w >= 0 else (-w, -x, -y, -z)
