"""Dead reckoning (IMU attitude + wheel odometry) on synthetic drives with known encoders and IMU."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from nav.dead_reckoning import (
    AttitudeEstimator,
    DeadReckoner,
    Pose,
    WheelOdometry,
    apply_vo_correction,
    roll_pitch_from_accel,
)
from nav.geometry import R_to_rpy, rpy_to_R, se3, se3_inv
from nav.types import STEERED, WHEELS, EncoderSample, ImuSample, RoverGeometry

GEOM = RoverGeometry()
G_MARS = 3.71
ENC_HZ, IMU_HZ = 8, 80


@dataclass
class Segment:
    duration_s: float
    v_m_s: float  # body forward speed
    w_rad_s: float  # yaw rate about the body z axis


def _wheel_command(v: float, w: float) -> tuple[np.ndarray, np.ndarray]:
    """Rolling speed (rad/s, WHEELS order) and steering (rad, STEERED order) for a body twist (v, 0, w)."""
    x, y = GEOM.wheel_xy_m[:, 0], GEOM.wheel_xy_m[:, 1]
    vx, vy = v - w * y, w * x
    heading = np.arctan2(vy, vx)
    speed = np.hypot(vx, vy)
    flip = np.abs(heading) > np.pi / 2 + 1e-9  # roll backwards instead of steering past 90 deg
    heading = np.where(flip, heading - np.sign(heading) * np.pi, heading)
    speed = np.where(flip, -speed, speed)
    steer = np.array([heading[WHEELS.index(n)] for n in STEERED])
    return speed / GEOM.wheel_radius_m, steer


def simulate_drive(segments: list[Segment], R_plane: np.ndarray = np.eye(3), origin=np.zeros(3), yaw0=0.0):
    """Truth and sensor streams of a rover driving on a plane (tilted by R_plane) through the segments.

    Between segments the rover stops for 0.25 s while the corner wheels steer (as MER did). Returns truth poses at
    the encoder times, the encoder samples, and IMU samples (gyro: body rate; accelerometer: R^T (0, 0, g)).
    """
    phases: list[Segment] = []
    for s in segments:
        phases += [Segment(0.25, 0.0, 0.0), s]
    # piecewise-constant commands, with the steering of the next driving phase applied during the stop before it
    t_end = sum(p.duration_s for p in phases) + 0.5
    bounds = np.cumsum([0.0] + [p.duration_s for p in phases])

    def phase_at(t):
        k = int(np.searchsorted(bounds, t, side="right") - 1)
        return phases[k] if k < len(phases) else Segment(1.0, 0.0, 0.0), k

    def steer_at(t):
        p, k = phase_at(t)
        if p.v_m_s == 0 and p.w_rad_s == 0 and k + 1 < len(phases):
            p = phases[k + 1]
        return _wheel_command(p.v_m_s, p.w_rad_s)[1]

    def state(t):
        """(x, y, theta) on the plane, cumulative wheel angle, by exact integration of arcs."""
        x = y = th = 0.0
        wheel = np.zeros(6)
        t0 = 0.0
        for p in phases + [Segment(1e9, 0.0, 0.0)]:
            dt = min(p.duration_s, t - t0)
            if dt <= 0:
                break
            v, w = p.v_m_s, p.w_rad_s
            if abs(w) < 1e-12:
                x, y = x + v * dt * np.cos(th), y + v * dt * np.sin(th)
            else:
                x += v / w * (np.sin(th + w * dt) - np.sin(th))
                y += -v / w * (np.cos(th + w * dt) - np.cos(th))
            th += w * dt
            wheel += _wheel_command(v, w)[0] * dt
            t0 += p.duration_s
        return x, y, th, wheel

    def pose(t):
        x, y, th, _ = state(t)
        R = R_plane @ rpy_to_R(0.0, 0.0, yaw0 + th)
        return se3(R, origin + R_plane @ rpy_to_R(0.0, 0.0, yaw0) @ np.array([x, y, 0.0]))

    t_enc = np.arange(0.0, t_end, 1.0 / ENC_HZ)
    truth = [pose(t) for t in t_enc]
    encoders = [EncoderSample(t, state(t)[3], steer_at(t)) for t in t_enc]
    t_imu = (np.arange(0, int(t_end * IMU_HZ)) + 0.5) / IMU_HZ
    imu = []
    for t in t_imu:
        R = pose(t)[:3, :3]
        w = phase_at(t)[0].w_rad_s
        imu.append(ImuSample(t, np.array([0.0, 0.0, w]), R.T @ np.array([0.0, 0.0, G_MARS])))
    return t_enc, truth, encoders, imu


def run_dead_reckoning(t_enc, truth, encoders, imu, level_at_rest=True) -> tuple[DeadReckoner, list[Pose]]:
    T0 = truth[0]
    dr = DeadReckoner(GEOM, Pose.from_matrix(T0, t_enc[0]), level_at_rest=level_at_rest)
    rest = [ImuSample(-0.1 * k, np.zeros(3), T0[:3, :3].T @ [0.0, 0.0, G_MARS]) for k in range(5, 0, -1)]
    dr.initialise_at_rest(rest, heading_rad=float(R_to_rpy(T0[:3, :3])[2]))
    poses = []
    t_imu = np.array([s.t_s for s in imu])
    prev_t = -np.inf
    for t, enc in zip(t_enc, encoders, strict=True):
        batch = [imu[i] for i in np.flatnonzero((t_imu > prev_t) & (t_imu <= t))]
        poses.append(dr.update(batch, enc))
        prev_t = t
    return dr, poses


def _heading_error_deg(T_est: np.ndarray, T_ref: np.ndarray) -> float:
    E = se3_inv(T_ref) @ T_est
    return float(np.degrees(np.arccos(np.clip((np.trace(E[:3, :3]) - 1) / 2, -1, 1))))


def test_straight_drive_reproduces_path():
    t, truth, enc, imu = simulate_drive([Segment(40.0, 0.05, 0.0)])
    _, poses = run_dead_reckoning(t, truth, enc, imu)
    for T, p in zip(truth, poses, strict=True):
        assert np.linalg.norm(p.position_xyz_m - T[:3, 3]) < 1e-6
    assert np.linalg.norm(poses[-1].position_xyz_m) == pytest.approx(2.0, abs=1e-6)


def test_arc_turn_in_place_and_straight_reproduce_path():
    segs = [Segment(20.0, 0.0375, 0.04), Segment(10.0, 0.0, -0.157), Segment(16.0, 0.05, 0.0), Segment(12, -0.04, 0.03)]
    t, truth, enc, imu = simulate_drive(segs, yaw0=0.3)
    dr, poses = run_dead_reckoning(t, truth, enc, imu)
    err = [np.linalg.norm(p.position_xyz_m - T[:3, 3]) for p, T in zip(poses, truth, strict=True)]
    dist = np.sum([abs(s.v_m_s) * s.duration_s for s in segs])
    assert max(err) < 0.002 * dist  # within 0.2 % of the distance driven (the MER goal was 10 %)
    assert _heading_error_deg(poses[-1].as_matrix(), truth[-1]) < 0.05
    assert dr.distance_m == pytest.approx(sum(s.v_m_s * s.duration_s for s in segs), rel=0.05)


def test_drive_up_a_slope_follows_the_tilted_body_axis():
    slope = np.radians(20.0)
    R_plane = rpy_to_R(0.0, -slope, 0.0)  # ground rises towards +x (east)
    t, truth, enc, imu = simulate_drive([Segment(30.0, 0.05, 0.0), Segment(20.0, 0.04, 0.03)], R_plane)
    _, poses = run_dead_reckoning(t, truth, enc, imu)
    p, T = poses[-1], truth[-1]
    assert np.linalg.norm(p.position_xyz_m - T[:3, 3]) < 0.005
    assert p.position_xyz_m[2] > 0.5  # climbed: 1.5 m up a 20 deg slope alone gives ~0.51 m
    rpy_est, rpy_ref = R_to_rpy(p.R_world_rover), R_to_rpy(T[:3, :3])
    np.testing.assert_allclose(rpy_est, rpy_ref, atol=np.radians(0.05))


def test_roll_pitch_from_accelerometers_at_rest():
    for roll, pitch in [(0.0, 0.0), (0.2, -0.1), (-0.4, 0.5)]:
        R = rpy_to_R(roll, pitch, 1.0)
        f = R.T @ np.array([0.0, 0.0, G_MARS])
        assert roll_pitch_from_accel(f) == pytest.approx((roll, pitch), abs=1e-12)
    att = AttitudeEstimator()
    R = rpy_to_R(0.1, 0.2, 0.7)
    att.level([ImuSample(0.0, np.zeros(3), R.T @ [0.0, 0.0, G_MARS])], yaw_rad=0.7)
    np.testing.assert_allclose(att.R_world_rover, R, atol=1e-12)


def test_gyro_integration_of_a_constant_rate():
    att = AttitudeEstimator()
    w = np.array([0.01, -0.02, 0.05])
    att.propagate([ImuSample(k / 100, w, np.zeros(3)) for k in range(1001)])  # 10 s
    from nav.geometry import so3_exp

    np.testing.assert_allclose(att.R_world_rover, so3_exp(w * 10.0), atol=1e-9)


def test_wheel_odometry_models():
    odo = WheelOdometry(GEOM)
    z4, z6 = np.zeros(4), np.zeros(6)
    # skid steering: the right wheels roll 0.02 m more than the left ones, no steering -> turn left
    right = np.array([0, 0, 0, 1, 1, 1], bool)
    angles = np.where(right, 0.12, 0.10) / GEOM.wheel_radius_m
    inc = odo.increment(EncoderSample(0, z6, z4), EncoderSample(1, angles, z4))
    assert inc.dyaw_rad == pytest.approx(0.02 / 1.1, rel=0.02)  # track 1.1 m; corner wheels skid sideways
    assert inc.dx_m == pytest.approx(0.11, rel=1e-3)
    # straight: every wheel 0.1 m
    inc = odo.increment(EncoderSample(0, z6, z4), EncoderSample(1, np.full(6, 0.1 / GEOM.wheel_radius_m), z4))
    assert (inc.dx_m, inc.dy_m, inc.dyaw_rad, inc.residual_m) == pytest.approx((0.1, 0.0, 0.0, 0.0), abs=1e-12)
    # steered arc about a centre 2 m to the left: exact, no residual
    rate, steer = _wheel_command(0.05, 0.025)
    inc = odo.increment(EncoderSample(0, z6, steer), EncoderSample(1, rate * 2.0, steer))
    assert inc.dyaw_rad == pytest.approx(0.05, rel=1e-9) and inc.residual_m < 1e-12
    assert np.hypot(inc.dx_m, inc.dy_m) == pytest.approx(2 * 2.0 * np.sin(0.025), rel=1e-9)  # chord
    # turn in place with the corner wheels steered tangentially
    rate, steer = _wheel_command(0.0, 0.3)
    inc = odo.increment(EncoderSample(0, z6, steer), EncoderSample(1, rate * 1.0, steer))
    assert inc.dyaw_rad == pytest.approx(0.3, rel=1e-9)
    assert abs(inc.dx_m) < 1e-12 and abs(inc.dy_m) < 1e-12 and abs(inc.distance_m) < 1e-12


def test_vo_correction_replaces_the_dead_reckoned_increment():
    """Slip: the wheels report 0.35 m, the rover made 0.20 m. VO's motion replaces the increment; DR continues."""
    t, truth, enc, imu = simulate_drive([Segment(7.0, 0.05, 0.0), Segment(7.0, 0.05, 0.0)], yaw0=0.5)
    dr, poses = run_dead_reckoning(t[:1], truth[:1], enc[:1], imu)
    start = dr.mark_vo_frame()
    t_imu = np.array([s.t_s for s in imu])
    i_mid = int(np.searchsorted(t, 7.25 + 1e-9))
    prev_t = t[0]
    for k in range(1, i_mid + 1):
        dr.update([imu[i] for i in np.flatnonzero((t_imu > prev_t) & (t_imu <= t[k]))], enc[k])
        prev_t = t[k]
    predicted = dr.predicted_motion_rover()
    assert predicted[0, 3] == pytest.approx(0.35, abs=1e-3)
    vo_motion = se3(rpy_to_R(0, 0, np.radians(0.2)), np.array([0.20, -0.01, 0.0]))  # what VO measured
    corrected = dr.apply_vo_correction(vo_motion)
    expected = start.as_matrix() @ vo_motion
    np.testing.assert_allclose(corrected.position_xyz_m, expected[:3, 3], atol=1e-12)
    np.testing.assert_allclose(corrected.quat_wxyz, dr.attitude.quat_wxyz)  # attitude stays the IMU's
    assert dr.vo_frame_pose.position_xyz_m == pytest.approx(corrected.position_xyz_m)
    np.testing.assert_allclose(dr.predicted_motion_rover(), np.eye(4), atol=1e-12)
    # dead reckoning continues from the corrected pose
    for k in range(i_mid + 1, len(t)):
        dr.update([imu[i] for i in np.flatnonzero((t_imu > prev_t) & (t_imu <= t[k]))], enc[k])
        prev_t = t[k]
    moved = dr.pose.position_xyz_m - corrected.position_xyz_m
    assert np.linalg.norm(moved) == pytest.approx(0.35, abs=2e-3)
    # VO failure: the dead-reckoned pose stands and becomes the new reference
    before = dr.pose
    after = dr.apply_vo_correction(None)
    np.testing.assert_allclose(after.position_xyz_m, before.position_xyz_m)
    # full 6-DOF variant
    p = apply_vo_correction(start, vo_motion, before, update_attitude=True)
    np.testing.assert_allclose(p.as_matrix(), start.as_matrix() @ vo_motion, atol=1e-12)


def test_attitude_propagation_equals_the_quaternion_array_form():
    """propagate() runs on plain floats for speed; it must give q <- qnorm(q (x) qexp(w dt)) per sample (the array
    helpers), including the tiny-angle branch and a gyro bias, to rounding: numpy's vectorised kernels may round
    differently from Python's scalar floats (numpy 2.4.6 on AVX-512: 7 units in the last place after 400 samples;
    earlier builds matched bit for bit)."""
    from nav.dead_reckoning import AttitudeEstimator, _qexp, _qmul, _qnorm

    rng = np.random.default_rng(4)
    for size in (1e-13, 1e-4, 0.05, 1.0):
        ts = [1.0 + 0.01 * k for k in range(400)]
        gyro = rng.normal(size=(len(ts), 3)) * size
        bias = rng.normal(size=3) * 1e-14
        q0 = rng.normal(size=4)
        est = AttitudeEstimator(q0, bias)
        samples = [ImuSample(t_s=t, gyro_rad_s=gyro[k], accel_m_s2=np.zeros(3)) for k, t in enumerate(ts)]
        for i in range(0, len(ts), 12):
            est.propagate(samples[i : i + 12])
        q = _qnorm(np.asarray(q0, float))
        for k in range(1, len(ts)):
            w = 0.5 * (gyro[k] + gyro[k - 1]) - bias
            q = _qnorm(_qmul(q, _qexp(w * (ts[k] - ts[k - 1]))))
        np.testing.assert_allclose(est.quat_wxyz, q, rtol=0.0, atol=1e-14)
