"""[sensors.odometry]: odometry and attitude errors, dead reckoning at 8 Hz, VO update modes,
and the segment / RMS error metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.trajectory import Pose, Trajectory
from nav.types import EncoderSample, ImuSample
from rover_sim.runtime.evaluator import (
    CHI2_3DOF_MEDIAN,
    VoStepError,
    rms_position_error_m,
    segment_errors_pct,
    vo_covariance_nees,
)
from rover_sim.runtime.onboard import Onboard
from rover_sim.runtime.run import run_scenario
from rover_sim.scenario.loading import scenario_from_dict
from rover_sim.scenario.odometry_spec import FLIGHT_DEFAULTS, OdometryErrorSpec
from rover_sim.scenario.sensors_spec import SensorsSpec
from rover_sim.sim.sensors import EncoderModel, ImuModel, OdometryErrors
from rover_sim.world.observation import Observation
from rover_sim.world.world import with_heading_error

# flat, firm, benign ground; VO off: the dead-reckoning acceptance bar on a short drive
FLAT = {
    "name": "flat_dr",
    "seed": 5,
    "terrain": {
        "size_m": [10, 6],
        "cell_size_m": 0.05,
        "roughness": {"rms_m": 0.003, "correlation_length_m": 2.0},
        "rocks": {"cover_fraction": 0.0},
        "material": {"kind": "bedrock"},
    },
    "start": {"x_m": -3.0, "y_m": 0.0},
    "nav": {"vo": False},
    "commands": [{"type": "drive", "distance_m": 3.0}],
}


def test_profiles_fill_the_odometry_table():
    assert SensorsSpec(profile="ideal").odometry.is_ideal
    flight = SensorsSpec(profile="flight").odometry
    assert flight.drawn_sizes() == FLIGHT_DEFAULTS and not flight.sinkage_rolling_radius  # opt-in (not small)
    mixed = SensorsSpec.model_validate({"profile": "flight", "odometry": {"heading_error_deg": 2.0}}).odometry
    assert mixed.heading_error_deg == 2.0 and mixed.steer_offset_deg == FLIGHT_DEFAULTS["steer_offset_deg"]
    with pytest.raises(ValueError, match="heading_error_deg"):
        OdometryErrorSpec(heading_error_deg=-1.0)


def test_ideal_draws_nothing_and_flight_is_seeded():
    none = OdometryErrors.draw(7, **SensorsSpec(profile="ideal").odometry.drawn_sizes())
    assert none == OdometryErrors.none()
    a = OdometryErrors.draw(7, **FLIGHT_DEFAULTS)
    b = OdometryErrors.draw(7, **FLIGHT_DEFAULTS)
    c = OdometryErrors.draw(8, **FLIGHT_DEFAULTS)
    assert np.array_equal(a.wheel_angle_scale, b.wheel_angle_scale) and a.heading_error_rad == b.heading_error_rad
    assert not np.array_equal(a.wheel_angle_scale, c.wheel_angle_scale)
    # a rotation scaled by 1 + O(300 ppm): close to, but not, the identity
    assert 0 < np.abs(a.gyro_matrix - np.eye(3)).max() < 0.01


def test_errors_corrupt_the_measurements():
    errs = OdometryErrors(
        wheel_angle_scale=np.full(6, 1 / 1.02), steer_offset_rad=np.full(4, 0.01), gyro_matrix=np.diag([1, 1, 1.001])
    )
    enc = EncoderModel(errors=errs).measure(0.0, np.full(6, 10.0), np.zeros(4))
    assert np.allclose(enc.wheel_angle_rad, 10.0 / 1.02, atol=1e-3)
    assert np.allclose(enc.steer_angle_rad, -0.01, atol=2e-3)
    imu = ImuModel(seed=1, errors=errs)
    imu.params = imu.params.__class__(gyro_arw_deg_sqrt_h=0.0, gyro_bias_instability_deg_h=0.0)
    imu.gyro_bias_rad_s[:] = 0.0
    gyro, _ = imu.corrupt(0.01, np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 3.7]]))
    assert gyro[0, 2] == pytest.approx(1.001, abs=1e-9)


def test_heading_error_turns_the_start_pose_only_about_the_vertical():
    pose = Pose(0.0, np.array([1.0, 2.0, 0.3]), np.array([math.cos(0.2), 0.0, math.sin(0.2), 0.0]))
    turned = with_heading_error(pose, math.radians(3.0))
    assert np.array_equal(turned.position_xyz_m, pose.position_xyz_m)
    assert turned.R_world_rover[2] == pytest.approx(pose.R_world_rover[2])  # tilt unchanged
    h0 = math.atan2(pose.R_world_rover[1, 0], pose.R_world_rover[0, 0])
    h1 = math.atan2(turned.R_world_rover[1, 0], turned.R_world_rover[0, 0])
    assert h1 - h0 == pytest.approx(math.radians(3.0))
    assert with_heading_error(pose, 0.0) is pose


def _onboard() -> Onboard:
    return Onboard(Pose.identity(), vo=None, stereo=None, planner_factory=lambda: None)  # type: ignore[arg-type]


def test_dead_reckoning_uses_every_encoder_sample():
    """Two encoder readings in one observation: both are folded in (8 Hz), each with the IMU samples up to it."""
    ob = _onboard()
    still = np.zeros(3), np.array([0.0, 0.0, 3.711])
    imu = [ImuSample(0.01 * k, *still) for k in range(26)]
    ob.observe(Observation(t_s=0.0, imu=tuple(imu[:1]), encoders=(EncoderSample(0.0, np.zeros(6), np.zeros(4)),)))
    turn = np.array([0.0, 0.0, 0.4])  # 0.4 rad/s yaw; the wheels roll 2 rad before 0.13 s, then stand
    imu2 = [ImuSample(0.01 * k, turn, still[1]) for k in range(1, 26)]
    encs = (EncoderSample(0.13, np.full(6, 2.0), np.zeros(4)), EncoderSample(0.25, np.full(6, 2.0), np.zeros(4)))
    ob.observe(Observation(t_s=0.25, imu=tuple(imu2), encoders=encs))
    # the displacement is rotated by the attitude in the middle of its own interval (yaw 0 -> 0.05 rad: 0.025);
    # folding in only the last reading (the old 4 Hz) would rotate it by the middle of 0 -> 0.098 rad (0.049)
    p = ob.dead_reckoning.pose.position_xyz_m
    r = ob.geometry.wheel_radius_m
    assert p[1] == pytest.approx(2 * r * math.sin(0.025), rel=0.03)
    assert ob.dead_reckoning.distance_m == pytest.approx(2 * r, rel=1e-6)


def test_vo_update_modes():
    with pytest.raises(ValueError, match="full_pose"):
        Onboard(Pose.identity(), None, None, lambda: None, vo_update="attitude")  # type: ignore[arg-type]
    ob = _onboard()
    est = ob.estimator
    est.mark_vo_frame()
    q_imu = est.pose.quat_wxyz.copy()
    motion = np.eye(4)
    motion[:3, :3] = [[math.cos(0.1), -math.sin(0.1), 0], [math.sin(0.1), math.cos(0.1), 0], [0, 0, 1]]
    motion[0, 3] = 0.3
    est.apply_vo_correction(motion, update_attitude=ob.vo_update == "full_pose")
    assert np.allclose(est.pose.quat_wxyz, q_imu)  # position only: the IMU keeps attitude
    assert est.pose.position_xyz_m[0] == pytest.approx(0.3)


def test_segment_and_rms_metrics_see_the_sawtooth():
    """An estimate that drifts 5 % between resets every 0.7 m: final error 0, segment and RMS errors not."""
    x = np.linspace(0.0, 6.0, 601)
    truth = Trajectory(np.arange(len(x)) * 0.1, np.stack([x, 0 * x, 0 * x], 1), np.tile([1.0, 0, 0, 0], (len(x), 1)))
    est_x = x + 0.05 * np.mod(x, 0.7)
    est_x[-1] = x[-1]
    est = Trajectory(truth.t_s, np.stack([est_x, 0 * x, 0 * x], 1), truth.orientations_quat_wxyz)
    seg = segment_errors_pct(est, truth)
    assert set(seg) == {"1m", "5m"}  # no 10 m segment in a 6 m drive
    assert 0.5 < seg["1m"] < 5.0
    rms = rms_position_error_m(est, truth)
    assert 0.01 < rms < 0.03  # 0.05 x a uniform 0-0.7 m ramp: RMS 0.05 x 0.7 / sqrt(3) = 0.020
    assert rms_position_error_m(truth, truth) == 0.0


def test_vo_covariance_nees_tells_consistent_optimistic_and_biased_covariances_apart():
    """Steps whose errors match their covariance score the chi-square median per step and over segments; a covariance
    ten times too small in sigma scores about 100 times that; an error common to every step (a calibration bias)
    passes per step but grows over segments. A refused step (None) ends a segment."""
    rng = np.random.default_rng(3)
    sigma, step_m, n = 0.002, 0.5, 400
    cov = sigma**2 * np.eye(3)

    def steps(err_sigma: float, bias: float = 0.0) -> list[VoStepError]:
        errs = rng.normal(0.0, err_sigma, (n, 3)) + bias
        return [VoStepError(step_m, e, cov) for e in errs]

    good = vo_covariance_nees(steps(sigma))
    assert abs(good["step_median"] - CHI2_3DOF_MEDIAN) < 0.5
    assert abs(good["segment_median"]["5m"] - CHI2_3DOF_MEDIAN) < 1.5
    assert vo_covariance_nees(steps(10 * sigma))["step_median"] > 50 * CHI2_3DOF_MEDIAN
    biased = vo_covariance_nees(steps(sigma, bias=sigma))
    assert biased["step_median"] < 3 * CHI2_3DOF_MEDIAN  # per step it looks almost fine ...
    # ... but summed over n steps the bias grows as n^2 against n: about 3 n + 3 (9 over 1 m, 33 over 5 m)
    assert biased["segment_median"]["5m"] > 5 * biased["step_median"]
    assert biased["segment_median"]["5m"] > 2.5 * biased["segment_median"]["1m"]
    # a refusal every 5 steps (2.5 m): no 5 m segment completes
    broken = [s if k % 5 else None for k, s in enumerate(steps(sigma))]
    assert vo_covariance_nees(broken)["segment_median"]["5m"] is None
    assert vo_covariance_nees([None, None]) is None


@pytest.mark.slow
def test_flight_dead_reckoning_is_worse_than_ideal_but_within_the_mer_goal(tmp_path):
    """The dead-reckoning bar on a short drive: flat benign ground, flight DR error > ideal and <= 10 % of distance."""
    ideal = run_scenario(scenario_from_dict(FLAT), tmp_path / "ideal", record=False)
    flight = run_scenario(scenario_from_dict(FLAT | {"sensors": {"profile": "flight"}}), tmp_path / "flight",
                          record=False)  # fmt: skip
    assert ideal.distance_m > 2.5 and flight.distance_m > 2.5
    assert flight.dr_error_pct > ideal.dr_error_pct
    assert flight.dr_error_pct <= 10.0
    assert flight.rms_position_error_m["dead_reckoning"] > ideal.rms_position_error_m["dead_reckoning"]
    assert flight.kitti_segment_error_pct["vo"] is None and "1m" in flight.kitti_segment_error_pct["dead_reckoning"]


def test_bench_suite_runs_both_profiles_and_gates_only_the_baseline_profile(tmp_path, monkeypatch, capsys):
    """Profile plumbing of `bench suite` with the runs stubbed out: each profile's rows are judged and printed, the
    regression gate judges only the baseline profile's run, --update-baseline stores it with its perturbed spread."""
    import json

    from rover_sim.apps.sweep_jobs import JobResult
    from rover_sim.bench import seeded, suite
    from rover_sim.bench.seeds import Seeds

    seen = []

    def fake_run_jobs(jobs, jobs_dir, *, on_result, **kw):
        for i, job in enumerate(jobs):
            profile = job.scenario["sensors"]["profile"]
            seen.append((profile, job.scenario["physics"]["perturb_size"]))
            vo = 0.2 + 0.01 * (job.seed - 200)
            m = {"scenario": job.scenario["name"], "seed": job.seed, "distance_m": 3.0, "dr_error_pct": 5.0,
                 "vo_error_pct": vo, "vo_convergence_pct": 100.0, "max_slip_pct": 4.0, "passed": True,
                 "reason": "all criteria met", "false_positives": 0, "goal_distance_m": None}  # fmt: skip
            on_result(i + 1, len(jobs), job, JobResult(job.job_id, "ok", metrics=m))
        return []

    monkeypatch.setattr(seeded, "run_jobs", fake_run_jobs)
    monkeypatch.setattr(suite, "scenario_names", lambda fast, only=(): ["wopmay"])
    seeds = Seeds(tuple(range(200, 212)), "gate")
    base = tmp_path / "base.json"
    r = suite.bench_suite(None, seeds, out_root=tmp_path, baseline_path=base, update_baseline=True, workers=0)
    assert r.passed and [p for p, _ in seen].count("ideal") == 12
    assert sorted({e for _, e in seen}) == [0.0, suite.SPREAD_PERTURBATION[0]]  # the spread run is perturbed
    out = capsys.readouterr().out
    assert "sensors profile: ideal" in out and "sensors profile: flight" in out
    assert "| wopmay | 1.00 | 3.00 [3.00, 3.00] |" in out
    stored = json.loads(base.read_text())
    assert stored["profile"] == suite.BASELINE_PROFILE and stored["seeds"] == list(seeds.values)
    assert stored["scenarios"]["wopmay"]["per_seed"]["vo_error_pct"]["205"] == pytest.approx(0.25)
    seen.clear()
    r = suite.bench_suite(None, seeds, fast=True, out_root=tmp_path, baseline_path=base, workers=0)
    assert {p for p, _ in seen} == {suite.BASELINE_PROFILE} and r.passed
    assert "regression gate" in capsys.readouterr().out
    assert r.data["profiles"]["flight"]["scenarios"]["wopmay"]["regression"]["vo_error_pct"]["regressed"] is False
