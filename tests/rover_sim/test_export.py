"""Dataset export: one short run written as KITTI, EuRoC and a ROS 2 bag at once, read back with
pykitti, plain CSV/YAML parsing and rosbags; ground truth against the run's truth.tum; strictly increasing stamps;
a rate export through the CLI leaves the run unchanged; bad options fail in one line."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from nav.geometry import quat_wxyz_to_R, se3, se3_inv
from nav.trajectory import Trajectory, read_tum
from rover_sim.cli.main import app
from rover_sim.io.export import FORMATS, export_scenario
from rover_sim.io.export.base import Stream

# the tiny scenario of test_runner.py as TOML (the CLI takes a file): 0.6 m up a 12 deg slope, VO every 0.3 m
TINY_TOML = """
name = "tiny"
seed = 3
start = { x_m = -2.0, y_m = 0.0 }
nav = { vo = true, vo_step_m = 0.3 }
commands = [{ type = "drive", distance_m = 0.6 }]

[terrain]
size_m = [8, 6]
cell_size_m = 0.05
slope = { slope_deg = 12, azimuth_deg = 0 }
rocks = { cover_fraction = 0.05, min_height_m = 0.05, max_height_m = 0.12, exclusion_zones = [[-2, 0, 1.0]] }
"""
NAVCAM_BASELINE_M = 0.20


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("scenario") / "tiny.toml"
    path.write_text(TINY_TOML)
    return path


@pytest.fixture(scope="module")
def exported(scenario_file, tmp_path_factory):
    """One run, all three formats into one directory (they do not overlap: sequences/ + poses/, mav0/, rosbag2/)."""
    out = tmp_path_factory.mktemp("export")
    summary = export_scenario(scenario_file, out, formats=FORMATS)
    return out, summary, last_per_stamp(read_tum(out / "run" / "trajectories" / "truth.tum"))


def last_per_stamp(traj: Trajectory) -> Trajectory:
    """The run's TUM files repeat a stamp when a pose is recorded again at the same instant: keep the last."""
    return traj[np.append(np.diff(traj.t_s) > 0, True)]


def increasing(t) -> bool:  # noqa: ANN001
    t = np.asarray(t, dtype=float)
    return len(t) > 0 and bool(np.all(np.diff(t) > 0))


def read_csv(path: Path) -> np.ndarray:
    with open(path) as f:
        rows = [r for r in csv.reader(f) if r and not r[0].startswith(("#", "t_s"))]
    return np.array([[float(x) for x in r] for r in rows])


def truth_at(truth: Trajectory, t_s: float) -> np.ndarray:
    i = int(np.argmin(np.abs(truth.t_s - t_s)))
    assert abs(truth.t_s[i] - t_s) < 1e-6, f"no truth.tum pose at {t_s}"
    return truth.matrices()[i]


def test_summary(exported):
    _, s, truth = exported
    assert s.frames == 3  # the first pair and one per VO step
    assert s.imu_samples > 1000  # 100 Hz over ~17 s
    assert s.duration_s == pytest.approx(truth.t_s[-1] - truth.t_s[0])
    assert s.dropped_duplicates == 0


# ---------------------------------------------------------------------------------------------------- KITTI
def test_kitti_reads_with_pykitti(exported):
    pykitti = pytest.importorskip("pykitti")
    out, s, _ = exported
    seq = pykitti.odometry(str(out), "00")
    assert len(seq.cam0_files) == len(seq.cam1_files) == len(seq.poses) == len(seq.timestamps) == s.frames
    assert seq.calib.b_gray == pytest.approx(NAVCAM_BASELINE_M, abs=1e-3)
    left, right = seq.get_gray(0)
    assert np.asarray(left).shape == (256, 256) and np.asarray(right).shape == (256, 256)
    np.testing.assert_allclose(seq.poses[0], np.eye(4), atol=1e-9)
    assert increasing([t.total_seconds() for t in seq.timestamps])


def test_kitti_poses_are_the_true_left_camera(exported):
    out, _, truth = exported
    seq = out / "sequences" / "00"
    calib = {k: np.array(v.split(), float) for k, v in (ln.split(":", 1) for ln in (seq / "calib.txt").open())}
    T_rover_cam = se3_inv(np.vstack([calib["Tr"].reshape(3, 4), [0, 0, 0, 1]]))
    times = np.loadtxt(seq / "times.txt", ndmin=1)
    poses = np.loadtxt(out / "poses" / "00.txt", ndmin=2).reshape(-1, 3, 4)
    T0 = truth_at(truth, times[0]) @ T_rover_cam
    for t, P in zip(times, poses, strict=True):
        expected = se3_inv(T0) @ truth_at(truth, t) @ T_rover_cam
        np.testing.assert_allclose(P, expected[:3], atol=2e-3)  # the mast's servo error is the only difference
    assert np.linalg.norm(poses[-1][:, 3]) > 0.3  # the camera moved with the rover
    imu, wheels = read_csv(seq / "imu.csv"), read_csv(seq / "wheels.csv")
    assert imu.shape[1] == 7 and wheels.shape[1] == 11
    assert increasing(times) and increasing(imu[:, 0]) and increasing(wheels[:, 0])
    assert wheels[-1, 1:7].mean() > wheels[0, 1:7].mean() + 4.0  # 0.6 m on 0.125 m wheels: ~4.8 rad


# ---------------------------------------------------------------------------------------------------- EuRoC
def test_euroc_layout_and_ground_truth(exported):
    from ruamel.yaml import YAML

    out, s, truth = exported
    mav = out / "mav0"
    cams = []
    for cam in ("cam0", "cam1"):
        rows = [r for r in csv.reader((mav / cam / "data.csv").open()) if not r[0].startswith("#")]
        assert len(rows) == s.frames and all((mav / cam / "data" / r[1]).is_file() for r in rows)
        cams.append([int(r[0]) for r in rows])
    assert cams[0] == cams[1] and increasing(cams[0])
    yaml = YAML(typ="safe")
    left, right = (yaml.load((mav / c / "sensor.yaml").read_text()) for c in ("cam0", "cam1"))
    assert left["camera_model"] == "pinhole" and left["resolution"] == [256, 256]
    T_BS0, T_BS1 = (np.array(y["T_BS"]["data"]).reshape(4, 4) for y in (left, right))
    assert np.linalg.norm((se3_inv(T_BS0) @ T_BS1)[:3, 3] - [NAVCAM_BASELINE_M, 0, 0]) < 1e-3  # right along +x
    assert yaml.load((mav / "imu0" / "sensor.yaml").read_text())["rate_hz"] == pytest.approx(100.0)
    imu = read_csv(mav / "imu0" / "data.csv")
    assert len(imu) == s.imu_samples and increasing(imu[:, 0])
    assert np.median(imu[:, 6]) == pytest.approx(3.71 * np.cos(np.radians(12)), abs=0.15)  # Mars g, 12 deg slope
    wheels = read_csv(mav / "wheels0" / "data.csv")
    assert wheels.shape[1] == 13 and increasing(wheels[:, 0])
    gt = read_csv(mav / "state_groundtruth_estimate0" / "data.csv")
    assert gt.shape[1] == 17 and increasing(gt[:, 0])
    np.testing.assert_allclose(gt[:, 0] * 1e-9, truth.t_s, atol=1e-9)
    np.testing.assert_allclose(gt[:, 1:4], truth.positions_xyz, atol=1e-8)
    np.testing.assert_allclose(gt[:, 4:8], truth.orientations_quat_wxyz, atol=1e-8)
    v_mid = (truth.positions_xyz[2:] - truth.positions_xyz[:-2]) / (truth.t_s[2:] - truth.t_s[:-2])[:, None]
    np.testing.assert_allclose(gt[1:-1, 8:11], v_mid, atol=1e-8)
    assert np.all(gt[:, 11:] == 0.0)


# ---------------------------------------------------------------------------------------------------- ROS 2
def test_rosbag2_reads_with_rosbags(exported):
    from rosbags.highlevel import AnyReader

    out, s, truth = exported
    with AnyReader([out / "rosbag2"]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        expected = {f"/navcam/{side}/{what}" for side in ("left", "right") for what in ("image_rect", "camera_info")}
        expected |= {"/imu/data", "/joint_states", "/odom/dead_reckoning", "/odom/vo", "/tf", "/tf_static"}
        assert set(counts) == expected
        assert counts["/navcam/left/image_rect"] == counts["/navcam/right/camera_info"] == s.frames
        assert counts["/imu/data"] == s.imu_samples
        assert counts["/tf"] == len(truth)
        stamps: dict[str, list[int]] = {}
        image = imu = info = None
        tf, odom = [], {}
        for conn, t, raw in reader.messages():
            stamps.setdefault(conn.topic, []).append(t)
            if conn.topic.startswith("/odom/"):
                p = reader.deserialize(raw, conn.msgtype).pose.pose.position
                odom.setdefault(conn.topic, []).append([t * 1e-9, p.x, p.y, p.z])
            if conn.topic == "/navcam/left/image_rect" and image is None:
                image = reader.deserialize(raw, conn.msgtype)
            elif conn.topic == "/imu/data" and imu is None:
                imu = reader.deserialize(raw, conn.msgtype)
            elif conn.topic == "/navcam/right/camera_info" and info is None:
                info = reader.deserialize(raw, conn.msgtype)
            elif conn.topic == "/tf":
                tf.append(reader.deserialize(raw, conn.msgtype).transforms[0])
    assert all(increasing(v) for v in stamps.values()), {k: len(v) for k, v in stamps.items()}
    import cv2

    first_png = sorted((out / "sequences" / "00" / "image_0").iterdir())[0]
    assert image.encoding == "mono8" and (image.height, image.width) == (256, 256)
    np.testing.assert_array_equal(image.data.reshape(256, 256), cv2.imread(str(first_png), cv2.IMREAD_GRAYSCALE))
    assert info.p[3] == pytest.approx(-info.k[0] * NAVCAM_BASELINE_M, rel=1e-3)
    first_imu = read_csv(out / "mav0" / "imu0" / "data.csv")[0]
    got = [imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z, imu.linear_acceleration.x,
           imu.linear_acceleration.y, imu.linear_acceleration.z]  # fmt: skip
    np.testing.assert_allclose(got, first_imu[1:], rtol=1e-8, atol=1e-12)
    assert imu.header.frame_id == "rover" and imu.orientation_covariance[0] == -1.0
    T = np.array([se3(quat_wxyz_to_R(np.array([r.w, r.x, r.y, r.z])), [p.x, p.y, p.z]) for p, r in
                  ((m.transform.translation, m.transform.rotation) for m in tf)])  # fmt: skip
    # truth is read back from the run's TUM file (9 decimals): a quaternion component carries +-5e-10, so a rotation
    # element up to about 2e-9
    np.testing.assert_allclose(T, truth.matrices(), atol=2e-9)
    assert tf[0].header.frame_id == "world" and tf[0].child_frame_id == "rover"
    for name in ("dead_reckoning", "vo"):  # the run's estimates, one per update (the last of each stamp)
        est = last_per_stamp(read_tum(out / "run" / "trajectories" / f"{name}.tum"))
        got = np.array(odom[f"/odom/{name}"])
        np.testing.assert_allclose(got[:, 0], est.t_s, atol=1e-9)
        np.testing.assert_allclose(got[:, 1:], est.positions_xyz, atol=1e-8)


# ---------------------------------------------------------------------------------------------------- CLI
def test_cli_rate_export_leaves_the_run_unchanged(exported, scenario_file, tmp_path):
    vo_steps_out, _, truth = exported
    out, summary = tmp_path / "rate", tmp_path / "summary.json"
    args = ["export", str(scenario_file), "--format", "kitti", "--out", str(out), "--rate-hz", "2"]
    res = CliRunner().invoke(app, [*args, "--json", str(summary), "--no-progress"])
    assert res.exit_code == 0, res.output
    data = json.loads(summary.read_text())
    assert set(data) == {"format", "frames", "imu_samples", "duration_s", "out", "reason"} and data["format"] == "kitti"
    assert data["reason"] == json.loads((out / "run" / "metrics.json").read_text())["reason"]
    assert data["frames"] == int(data["duration_s"] * 2) + 1  # 2 Hz from the first tick
    assert len(np.loadtxt(out / "sequences" / "00" / "times.txt")) == data["frames"]
    for name in ("truth", "dead_reckoning", "vo"):  # the noise-free extra renders drew nothing from the run's RNG
        a = (out / "run" / "trajectories" / f"{name}.tum").read_text()
        assert a == (vo_steps_out / "run" / "trajectories" / f"{name}.tum").read_text(), name
    import cv2

    # the extra renders are rectified like the rover's own pairs (flight profile: raw renders, rectified here): the
    # first frame, at the same instant as the first VO pair, differs from it by little more than the image noise
    rate0, vo0 = (cv2.imread(str(d / "sequences" / "00" / "image_0" / "000000.png"), cv2.IMREAD_GRAYSCALE)
                  for d in (out, vo_steps_out))  # fmt: skip
    assert np.abs(rate0.astype(float) - vo0).mean() < 2.0  # unrectified raw images: about 7 grey levels


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--format", "bag"], ["--format", "kitti, euroc, rosbag2"]),
        (["--camera", "pancam"], ["--camera", "navcam, hazcam_front, hazcam_rear"]),
        (["--rate-hz", "0"], ["--rate-hz", "> 0", "<= 8"]),
        (["--rate-hz", "9"], ["--rate-hz", "<= 8"]),
        (["--rate-hz", "2", "--at-vo-steps"], ["--rate-hz", "--at-vo-steps"]),
    ],
)
def test_cli_bad_options_fail_in_one_line(args, words, tmp_path):
    res = CliRunner().invoke(app, ["export", "wopmay", "--out", str(tmp_path / "x"), *args])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "Traceback" not in res.output, res.output
    assert all(w in lines[0] for w in words), lines[0]
    assert not (tmp_path / "x").exists()


# ---------------------------------------------------------------------------------------------------- pieces
def test_stream_keeps_first_image_and_last_pose():
    got_first, got_last = [], []
    first, last = Stream(got_first.append), Stream(got_last.append, keep="last")
    for t, item in [(0.0, "a"), (1.0, "b"), (1.0, "c"), (0.5, "d"), (2.0, "e")]:
        first.push(t, item)
        last.push(t, item)
    last.flush()
    assert got_first == ["a", "b", "e"] and got_last == ["a", "c", "e"]
    assert first.count == last.count == 3 and first.dropped == last.dropped == 2
