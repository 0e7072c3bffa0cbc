"""IMU noise statistics against the configured LN-200 model, accelerometer tilt, encoders, mast pointing."""

from __future__ import annotations

import math

import numpy as np
import pytest

import rover_sim  # noqa: F401
from rover_sim.sim.physics import RoverSim
from rover_sim.sim.sensors import (
    G0_M_S2,
    EncoderModel,
    EncoderParams,
    ImuModel,
    ImuParams,
    SensorSuite,
    point_mast,
    roll_pitch_from_accel,
    tilt_from_accel_deg,
)
from terrains import RockSpec, RoughnessSpec, TerrainRecipe, synthesize

MARS_G = 3.711
RATE_HZ = 100.0
TEN_MIN_S = 600.0


def allan_deviation(x: np.ndarray, dt_s: float, tau_s: float) -> np.ndarray:
    """Non-overlapping Allan deviation of rate samples ``x`` (N, k) at averaging time ``tau_s``."""
    m = int(round(tau_s / dt_s))
    n = len(x) // m
    means = x[: n * m].reshape(n, m, -1).mean(axis=1)
    return np.sqrt(0.5 * np.mean(np.diff(means, axis=0) ** 2, axis=0))


@pytest.fixture(scope="module")
def sensor_static_runs() -> tuple[ImuParams, np.ndarray, np.ndarray]:
    """64 independent IMUs at rest (level, Mars gravity), 10 min at 100 Hz each: gyro (64, N, 3), accel."""
    params = ImuParams(rate_hz=RATE_HZ)
    n = int(TEN_MIN_S * RATE_HZ)
    gyro_true, accel_true = np.zeros((n, 3)), np.tile([0.0, 0.0, MARS_G], (n, 1))
    gyros, accels = [], []
    for seed in range(64):
        g, a = ImuModel(params, seed=seed).corrupt(1.0 / RATE_HZ, gyro_true, accel_true)
        gyros.append(g)
        accels.append(a)
    return params, np.array(gyros), np.array(accels)


def test_sensor_gyro_angle_random_walk_from_allan_deviation(sensor_static_runs) -> None:
    params, gyro, _ = sensor_static_runs
    # white rate noise of density N: Allan deviation N / sqrt(tau) (bias instability is 100x smaller at 1 s)
    adev = np.array([allan_deviation(g, 1.0 / RATE_HZ, 1.0) for g in gyro[:8]])
    arw_deg_sqrt_h = float(np.median(adev)) / (math.pi / 180.0) * 60.0
    assert 0.5 * params.gyro_arw_deg_sqrt_h < arw_deg_sqrt_h < 2.0 * params.gyro_arw_deg_sqrt_h
    assert arw_deg_sqrt_h == pytest.approx(0.07, rel=0.15)


def test_sensor_gyro_drift_over_ten_minutes_matches_model(sensor_static_runs) -> None:
    """Std of the integrated heading error after 10 min at rest = ARW walk + Gauss-Markov bias integral."""
    params, gyro, _ = sensor_static_runs
    angle = gyro.sum(axis=1) / RATE_HZ  # (64, 3) integrated angle, rad
    measured = float(np.sqrt(np.mean(angle**2)))
    T, tc, sb = TEN_MIN_S, params.gyro_bias_corr_time_s, params.gyro_bias_rad_s
    bias_var = 2.0 * sb**2 * tc**2 * (T / tc - 1.0 + math.exp(-T / tc))
    predicted = math.sqrt(params.gyro_white_rad_sqrt_s**2 * T + bias_var)  # 0.15 deg
    assert 0.5 * predicted < measured < 2.0 * predicted, (math.degrees(measured), math.degrees(predicted))
    # the bias term dominates: a model without bias would predict only 0.029 deg
    assert measured > 2.0 * params.gyro_white_rad_sqrt_s * math.sqrt(T)
    # "drift < 3 deg per hour" (MER): the 10-min heading error stays far below that
    assert math.degrees(np.abs(angle).max()) < 3.0 * TEN_MIN_S / 3600.0


def test_sensor_accelerometer_white_noise_is_50_micro_g(sensor_static_runs) -> None:
    params, _, accel = sensor_static_runs
    one_second = accel[:8].reshape(8, int(TEN_MIN_S), int(RATE_HZ), 3).mean(axis=2)  # 1 s averages
    noise_ug = float(one_second.std(axis=1).mean()) / G0_M_S2 * 1e6  # micro (Earth) g in a 1 s average
    assert 0.5 * params.accel_noise_ug_sqrt_hz < noise_ug < 2.0 * params.accel_noise_ug_sqrt_hz
    assert accel[..., 2].mean() == pytest.approx(MARS_G, abs=1e-5)


def test_sensor_imu_seeded_and_rate_independent() -> None:
    a = ImuModel(seed=3).corrupt(0.01, np.zeros((50, 3)), np.zeros((50, 3)))
    b = ImuModel(seed=3).corrupt(0.01, np.zeros((50, 3)), np.zeros((50, 3)))
    np.testing.assert_array_equal(a[0], b[0])
    # per-sample std scales as 1/sqrt(dt): the same angle random walk at 50 Hz and 400 Hz
    for rate in (50.0, 400.0):
        g, _ = ImuModel(seed=1).corrupt(1.0 / rate, np.zeros((20000, 3)), np.zeros((20000, 3)))
        assert g.std() * math.sqrt(1.0 / rate) == pytest.approx(ImuParams().gyro_white_rad_sqrt_s, rel=0.05)


def test_sensor_imu_on_the_real_rover_at_rest() -> None:
    """SensorSuite on RoverSim: parked on level ground, 5 s at 100 Hz; noise as configured, gravity right."""
    terrain = synthesize(
        TerrainRecipe(size_m=(6.0, 6.0), roughness=RoughnessSpec(rms_m=0.0), rocks=RockSpec(cover_fraction=0.0)), 0
    )
    sim = RoverSim(terrain)
    sim.place(0.0, 0.0, 0.3, settle_s=2.0)
    suite = SensorSuite(sim, seed=7)
    suite.poll()
    sim.step_for(5.0)
    imu, enc = suite.poll()
    assert len(imu) == pytest.approx(5.0 * RATE_HZ, abs=1) and len(enc) == pytest.approx(5.0 * 8, abs=1)
    t = np.array([s.t_s for s in imu])
    np.testing.assert_allclose(np.diff(t), 1.0 / RATE_HZ, atol=1e-9)
    gyro = np.array([s.gyro_rad_s for s in imu])
    accel = np.array([s.accel_m_s2 for s in imu])
    p = suite.imu.params
    sigma_gyro = p.gyro_white_rad_sqrt_s * math.sqrt(RATE_HZ)
    assert np.all((0.5 * sigma_gyro < gyro.std(axis=0)) & (gyro.std(axis=0) < 2.0 * sigma_gyro))
    assert np.all(np.abs(gyro.mean(axis=0)) < 5.0 * p.gyro_bias_rad_s + 5.0 * sigma_gyro / math.sqrt(len(gyro)))
    sigma_accel = p.accel_white_m_s2_sqrt_hz * math.sqrt(RATE_HZ)
    assert np.all((0.5 * sigma_accel < accel.std(axis=0)) & (accel.std(axis=0) < 2.0 * sigma_accel))
    assert np.linalg.norm(accel.mean(axis=0)) == pytest.approx(MARS_G, rel=1e-3)
    assert tilt_from_accel_deg(accel.mean(axis=0)) == pytest.approx(sim.tilt_deg(), abs=0.2)


def test_sensor_accelerometer_tilt_on_a_slope(sensor_slope_sim) -> None:
    sim = sensor_slope_sim
    suite = SensorSuite(sim, seed=1)
    try:
        sim.step_for(1.0)
        imu, _ = suite.poll()
    finally:
        suite.detach()
    accel = np.array([s.accel_m_s2 for s in imu]).mean(axis=0)
    assert sim.tilt_deg() > 12.0  # really on the slope
    assert tilt_from_accel_deg(accel) == pytest.approx(sim.tilt_deg(), abs=0.2)
    # roll and pitch against the true attitude (ZYX Euler of the body)
    R = sim.rotation()
    roll_true, pitch_true = math.atan2(R[2, 1], R[2, 2]), -math.asin(R[2, 0])
    roll, pitch = roll_pitch_from_accel(accel)
    assert math.degrees(abs(roll - roll_true)) < 0.2 and math.degrees(abs(pitch - pitch_true)) < 0.2


def test_sensor_encoders_quantise() -> None:
    params = EncoderParams()
    enc = EncoderModel(params)
    wheel = np.array([0.0, 1e-5, -1e-5, 3.0, -7.25, 100.123456])
    steer = np.array([0.0, 0.3, -0.7, 1.5])
    s = enc.measure(1.0, wheel, steer)
    qw, qs = params.wheel_quantum_rad, params.steer_quantum_rad
    np.testing.assert_allclose(s.wheel_angle_rad / qw, np.round(s.wheel_angle_rad / qw), atol=1e-9)
    assert np.all((wheel - s.wheel_angle_rad >= 0) & (wheel - s.wheel_angle_rad < qw))  # counter: truncation
    assert np.all(np.abs(steer - s.steer_angle_rad) <= 0.5 * qs + 1e-12)
    assert s.wheel_angle_rad[1] == 0.0 and s.wheel_angle_rad[2] == -qw
    assert qw == pytest.approx(2 * math.pi / 2**14) and math.degrees(qs) == pytest.approx(0.088, abs=1e-3)


def test_sensor_encoders_follow_the_wheels(sensor_slope_sim) -> None:
    sim = sensor_slope_sim
    suite = SensorSuite(sim, seed=0)
    try:
        sim.step_for(1.0, wheel_rate_rad_s=np.full(6, 0.3))
        _, enc = suite.poll()
    finally:
        suite.detach()
        sim.hold()
    assert 8 <= len(enc) <= 10
    q = suite.encoders.params.wheel_quantum_rad
    assert np.all(np.abs(enc[-1].wheel_angle_rad - sim.wheel_angles_rad()) < 0.3 * 0.02 + q)
    assert np.all(np.diff([e.wheel_angle_rad for e in enc], axis=0) > 0)  # rolling forward, counts increase


def test_sensor_point_mast(sensor_slope_sim) -> None:
    sim = sensor_slope_sim
    try:
        achieved = point_mast(sim, -0.8, 0.7)
        np.testing.assert_allclose(achieved, [-0.8, 0.7], atol=1e-3)
        with pytest.raises(ValueError, match="mast_tilt"):
            point_mast(sim, 0.0, 2.0)
    finally:
        point_mast(sim, 0.0, 0.0)


def test_batched_imu_measurements_equal_one_at_a_time() -> None:
    """The suite corrupts a tick's samples in one batch (ImuModel.measure_many): the numbers must be exactly those
    of one ``measure`` call per sample, with mounting/scale errors and uneven sample spacing."""
    from rover_sim.sim.sensors import OdometryErrors

    errors = OdometryErrors.draw(7, imu_misalignment_mrad=1.0, gyro_scale_factor_ppm=100.0,
                                 accel_scale_factor_ppm=100.0)  # fmt: skip
    rng = np.random.default_rng(0)
    ts = [1.0 + 0.005 * k for k in range(0, 1200, 2)]  # float steps: the spacing varies in its last bits
    gyro, accel = rng.normal(size=(len(ts), 3)), rng.normal(size=(len(ts), 3)) + [0.0, 0.0, MARS_G]
    for err in (errors, OdometryErrors.none()):
        one, many = ImuModel(seed=3, errors=err), ImuModel(seed=3, errors=err)
        a = [one.measure(t, gyro[k], accel[k]) for k, t in enumerate(ts)]
        b = []
        for i in range(0, len(ts), 13):
            b += many.measure_many(ts[i : i + 13], gyro[i : i + 13], accel[i : i + 13])
        assert [s.t_s for s in a] == [s.t_s for s in b]
        np.testing.assert_array_equal([s.gyro_rad_s for s in a], [s.gyro_rad_s for s in b])
        np.testing.assert_array_equal([s.accel_m_s2 for s in a], [s.accel_m_s2 for s in b])
        np.testing.assert_array_equal(one.gyro_bias_rad_s, many.gyro_bias_rad_s)
    with pytest.raises(ValueError, match="forward in time"):
        ImuModel(seed=1).measure_many([1.0, 1.0], np.zeros((2, 3)), np.zeros((2, 3)))
