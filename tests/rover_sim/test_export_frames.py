"""Ground truth in the exported images' frame, and the Kalibr/OpenVINS calibration beside a EuRoC export.

On the flight profile the exported images are rectified through the calibrated models, so the camera they are in
is turned from the physical navcam by the mounting, rectifying and calibration rotations (0.1-0.2 deg). Every
format's ground truth (KITTI ``Tr`` + ``poses/``, EuRoC ``T_BS`` + ground truth, the bag's ``/tf_static`` +
``/tf``) must be that rectified camera's pose, checked two ways:

(a) against the project's own rectification objects: the remap table the onboard stack rectified the first pair
    with and the true lens model give the true ray of every rectified pixel; the exported orientation must carry
    the rectified rays onto them to <= 0.02 deg (and the physical camera's does not);
(b) from the images: the rotation fitted between the flight and ideal exports' first left images of the same
    drive (KLT matches, the ideal pair's stereo depth) agrees to <= 0.02 deg with the rotation between their
    exported truth orientations.

The Kalibr ``camchain-imucam.yaml`` (``T_cam_imu``) and OpenVINS ``kalibr_imucam_chain.yaml`` (``T_imu_cam``, the
inverse) reproject a world point through the exported truth onto the same pixel as the EuRoC/KITTI camera model
(<= 0.01 px).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nav.geometry import quat_wxyz_to_R, se3, se3_inv
from rover_sim.io.export import FORMATS, DatasetSink, make_writer
from rover_sim.io.export.kalibr import CAMCHAIN, IMU, OPENVINS_CAMCHAIN, OPENVINS_IMU
from rover_sim.scenario.loading import scenario_from_dict

TOL_DEG = 0.02
TINY = {
    "name": "tiny",
    "seed": 3,
    "start": {"x_m": -2.0},
    "nav": {"vo": True, "vo_step_m": 0.3},
    "commands": [{"type": "drive", "distance_m": 0.6}],
    "terrain": {"size_m": [8, 6], "cell_size_m": 0.05, "slope": {"slope_deg": 12, "azimuth_deg": 0},
                "rocks": {"cover_fraction": 0.05, "min_height_m": 0.05, "max_height_m": 0.12,
                          "exclusion_zones": [[-2, 0, 1.0]]}},
}  # fmt: skip


def export_with_objects(out: Path, profile: str, distance_m: float) -> dict:
    """Run the tiny drive with a sink writing every format (and OpenVINS's files), keeping the objects the first
    navcam pair was rectified with: the calibration, its rectification and the true raw models at capture."""
    from nav.rectify import rectification
    from rover_sim.runtime.run import write_outputs
    from rover_sim.runtime.runner import Mission

    sc = scenario_from_dict(TINY, "tiny", [f'sensors.profile="{profile}"', f"commands.0.distance_m={distance_m}"])
    mission = Mission(sc)
    out.mkdir(parents=True, exist_ok=True)
    sink = DatasetSink([make_writer(f, out, openvins=f == "euroc") for f in FORMATS], "navcam").attach(mission)
    first: dict = {}

    def keep_first(obs, truth) -> None:  # noqa: ANN001 - after the sink: the pair is rectified by now
        if "navcam" in obs.images and not first:
            calib = mission.onboard.rectifying_calibration(obs, "navcam")
            rig = mission.world.renderer.rig("navcam")  # the mast as it physically stands
            lens = mission.world.calibration
            first.update(truth=truth, physical=rig.left.T_rover_cam, calib=calib,
                         rect=None if calib is None else rectification(calib),
                         true_left=None if lens is None else lens.true_model(rig.left),
                         true_right=None if lens is None else lens.true_model(rig.right))  # fmt: skip

    mission.image_listeners.append(keep_first)
    try:
        metrics = mission.run()
    finally:
        sink.close()
        mission.close()
    write_outputs(mission, metrics, out / "run")
    return {"out": out, **first}


@pytest.fixture(scope="module")
def flight(tmp_path_factory) -> dict:
    return export_with_objects(tmp_path_factory.mktemp("flight"), "flight", 0.3)


@pytest.fixture(scope="module")
def ideal(tmp_path_factory) -> dict:
    return export_with_objects(tmp_path_factory.mktemp("ideal"), "ideal", 0.3)  # the first frame is all we use


# ------------------------------------------------------------------------------------ reading the three formats
def first_frame_t_s(out: Path) -> float:
    return float(np.loadtxt(out / "sequences" / "00" / "times.txt", ndmin=1)[0])


def kitti_world_cam(out: Path) -> np.ndarray:
    """T_world_cam0 of the first frame: KITTI ``Tr`` (rover -> cam0) with the run's truth.tum at that time."""
    seq = out / "sequences" / "00"
    calib = {k: np.array(v.split(), float) for k, v in (ln.split(":", 1) for ln in (seq / "calib.txt").open())}
    Tr = np.vstack([calib["Tr"].reshape(3, 4), [0, 0, 0, 1]])
    rows = np.loadtxt(out / "run" / "trajectories" / "truth.tum", ndmin=2)
    r = rows[np.flatnonzero(np.abs(rows[:, 0] - first_frame_t_s(out)) < 1e-6)[-1]]
    T_world_rover = se3(quat_wxyz_to_R(np.array([r[7], r[4], r[5], r[6]])), r[1:4])
    assert np.allclose(np.loadtxt(out / "poses" / "00.txt", ndmin=2)[0], np.eye(4)[:3].ravel(), atol=1e-9)
    return T_world_rover @ se3_inv(Tr)


def euroc_truth_rover(out: Path, t_s: float) -> np.ndarray:
    with open(out / "mav0" / "state_groundtruth_estimate0" / "data.csv") as f:
        rows = np.array([[float(x) for x in r] for r in csv.reader(f) if r and not r[0].startswith("#")])
    r = rows[np.argmin(np.abs(rows[:, 0] - round(t_s * 1e9)))]
    assert abs(r[0] * 1e-9 - t_s) < 1e-6
    return se3(quat_wxyz_to_R(r[4:8]), r[1:4])


def euroc_sensor(out: Path, cam: str) -> dict:
    from ruamel.yaml import YAML

    return YAML(typ="safe").load((out / "mav0" / cam / "sensor.yaml").read_text())


def euroc_world_cam(out: Path) -> np.ndarray:
    T_BS = np.array(euroc_sensor(out, "cam0")["T_BS"]["data"]).reshape(4, 4)
    return euroc_truth_rover(out, first_frame_t_s(out)) @ T_BS


def rosbag_world_cam(out: Path) -> np.ndarray:
    """T_world_cam of the first frame from the bag: ``/tf`` (world -> rover) at its stamp, ``/tf_static``."""
    from rosbags.highlevel import AnyReader

    def matrix(tf) -> np.ndarray:  # noqa: ANN001
        q, p = tf.transform.rotation, tf.transform.translation
        return se3(quat_wxyz_to_R(np.array([q.w, q.x, q.y, q.z])), [p.x, p.y, p.z])

    stamp = round(first_frame_t_s(out) * 1e9)
    T_world_rover = T_rover_cam = None
    with AnyReader([out / "rosbag2"]) as reader:
        for conn, t, raw in reader.messages():
            if conn.topic == "/tf_static" and T_rover_cam is None:
                tfs = reader.deserialize(raw, conn.msgtype).transforms
                T_rover_cam = matrix(next(tf for tf in tfs if tf.child_frame_id == "navcam_left"))
            elif conn.topic == "/tf" and t == stamp:
                T_world_rover = matrix(reader.deserialize(raw, conn.msgtype).transforms[0])
    assert T_world_rover is not None and T_rover_cam is not None
    return T_world_rover @ T_rover_cam


WORLD_CAM = {"kitti": kitti_world_cam, "euroc": euroc_world_cam, "rosbag2": rosbag_world_cam}


def angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    return float(np.degrees(Rotation.from_matrix(R_a[:3, :3].T @ R_b[:3, :3]).magnitude()))


# ------------------------------------------------------------------------- (a) the rectification objects
def true_rays_of_rectified_pixels(rect_cam, table, true_model) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """(rectified rays in the rectified frame, true rays in the rover frame) of a grid of rectified pixels: the
    raw pixel each one samples is read from the remap table the onboard stack used."""
    v, u = np.mgrid[4 : rect_cam.height_px - 4 : 6, 4 : rect_cam.width_px - 4 : 6]
    raw = np.stack([table[0][v, u].ravel(), table[1][v, u].ravel()], axis=1).astype(float)
    rays = np.stack([(u.ravel() - rect_cam.cx_px) / rect_cam.fx_px, (v.ravel() - rect_cam.cy_px) / rect_cam.fy_px,
                     np.ones(u.size)], axis=1)  # fmt: skip
    d = true_model.unproject(raw) @ true_model.T_rover_cam[:3, :3].T
    return rays / np.linalg.norm(rays, axis=1, keepdims=True), d / np.linalg.norm(d, axis=1, keepdims=True)


def median_ray_error_deg(R_rover_cam: np.ndarray, rays: np.ndarray, true_rays: np.ndarray) -> float:
    cos = np.clip(np.sum((rays @ R_rover_cam[:3, :3].T) * true_rays, axis=1), -1.0, 1.0)
    return float(np.degrees(np.median(np.arccos(cos))))


@pytest.mark.parametrize("fmt", FORMATS)
def test_truth_is_the_rectified_camera_by_the_rectification_objects(flight, fmt):
    assert flight["rect"] is not None, "the flight profile rectifies raw pairs"
    rect_cam = flight["rect"].rig.left
    rays, true_rays = true_rays_of_rectified_pixels(rect_cam, flight["rect"].left_map, flight["true_left"])
    T_rover_world = se3_inv(flight["truth"].as_matrix())
    T_rover_cam = T_rover_world @ WORLD_CAM[fmt](flight["out"])
    fitted, _ = Rotation.align_vectors(true_rays, rays)  # the rectified camera's true orientation, from the table
    exported_deg = angle_deg(T_rover_cam, fitted.as_matrix())
    physical_deg = angle_deg(flight["physical"], fitted.as_matrix())
    residual = median_ray_error_deg(T_rover_cam, rays, true_rays)  # what no pose absorbs: focal, distortion errors
    print(f"\n{fmt}: exported vs rectified camera {exported_deg:.4f} deg (physical camera: {physical_deg:.4f} deg); "
          f"median ray residual {residual:.4f} deg")  # fmt: skip
    assert exported_deg <= TOL_DEG
    assert physical_deg > 3 * TOL_DEG  # the frame the exports used to give: the check can fail
    np.testing.assert_allclose(T_rover_cam[:3, 3], flight["physical"][:3, 3], atol=1e-6)  # the true optical centre


def test_right_camera_truth_is_the_rectified_right_camera(flight):
    rect_cam = flight["rect"].rig.right
    rays, true_rays = true_rays_of_rectified_pixels(rect_cam, flight["rect"].right_map, flight["true_right"])
    T_BS = np.array(euroc_sensor(flight["out"], "cam1")["T_BS"]["data"]).reshape(4, 4)
    fitted, _ = Rotation.align_vectors(true_rays, rays)
    assert angle_deg(T_BS, fitted.as_matrix()) <= TOL_DEG
    np.testing.assert_allclose(T_BS[:3, 3], flight["true_right"].T_rover_cam[:3, 3], atol=1e-9)


# -------------------------------------------------------------------------------------------- (b) the images
def image_rotation(flight_out: Path, ideal_out: Path, t_flight_ideal: np.ndarray) -> tuple[np.ndarray, int]:
    """R_flightcam_idealcam fitted from the first left images: corners of the ideal image, their depth from the
    ideal pair (KLT along the rows), tracked into the flight image (KLT, forward-backward checked); then the
    rotation carrying each 3D point (ideal camera frame, moved by the known ``t_flight_ideal``, a few hundredths
    of a millimetre here) onto its flight ray (least squares, Wahba)."""
    seq = [d / "sequences" / "00" for d in (flight_out, ideal_out)]
    fl, il, ir = (cv2.imread(str(s / f"image_{i}" / "000000.png"), cv2.IMREAD_GRAYSCALE)
                  for s, i in ((seq[0], 0), (seq[1], 0), (seq[1], 1)))  # fmt: skip

    def P(s: Path) -> dict:
        return {k: np.array(v.split(), float) for k, v in (ln.split(":", 1) for ln in (s / "calib.txt").open())}

    Kf, Ki = P(seq[0])["P0"].reshape(3, 4)[:, :3], P(seq[1])["P0"].reshape(3, 4)[:, :3]
    baseline = -P(seq[1])["P1"][3] / Ki[0, 0]
    lk = {"winSize": (15, 15), "maxLevel": 3, "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)}

    def normalised(img: np.ndarray) -> np.ndarray:  # the two profiles expose differently: match the statistics
        f = img.astype(np.float32)
        return np.clip((f - f.mean()) / f.std() * 40.0 + 128.0, 0, 255).astype(np.uint8)

    def track(a: np.ndarray, b: np.ndarray, pts: np.ndarray, guess: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        fwd, s1, _ = cv2.calcOpticalFlowPyrLK(a, b, pts, guess.copy(), **lk)
        back, s2, _ = cv2.calcOpticalFlowPyrLK(b, a, fwd, pts.copy(), **lk)
        return fwd, (s1.ravel() == 1) & (s2.ravel() == 1) & (np.linalg.norm(back - pts, axis=1) < 0.1)

    pts = cv2.goodFeaturesToTrack(il, 3000, 0.005, 4).reshape(-1, 2).astype(np.float32)
    right, ok_stereo = track(il, ir, pts, pts - np.float32([8.0, 0.0]))
    disparity = pts[:, 0] - right[:, 0]
    ok_stereo &= (np.abs(right[:, 1] - pts[:, 1]) < 0.2) & (disparity > 2.0)
    in_flight, ok_flight = track(normalised(il), normalised(fl), pts, pts)
    ok = ok_stereo & ok_flight
    z = Ki[0, 0] * baseline / disparity[ok]
    X = np.stack([(pts[ok, 0] - Ki[0, 2]) / Ki[0, 0] * z, (pts[ok, 1] - Ki[1, 2]) / Ki[1, 1] * z, z], axis=1)
    uv = in_flight[ok]
    b = np.stack([(uv[:, 0] - Kf[0, 2]) / Kf[0, 0], (uv[:, 1] - Kf[1, 2]) / Kf[1, 1], np.ones(len(uv))], axis=1)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    R = np.eye(3)
    for _ in range(2):  # x_flight = R x_ideal + t: the rays of R^T x_flight = x_ideal + R^T t
        a = X + R.T @ t_flight_ideal
        fit, _ = Rotation.align_vectors(b, a / np.linalg.norm(a, axis=1, keepdims=True))
        R = fit.as_matrix()
    residual = np.arccos(
        np.clip(
            np.sum(
                b * ((X + R.T @ t_flight_ideal) @ R.T / np.linalg.norm(X + R.T @ t_flight_ideal, axis=1)[:, None]), 1
            ),
            -1,
            1,
        )
    )
    inliers = residual < 3 * np.median(residual)  # a bad match or two: refit without them
    a = X[inliers] + R.T @ t_flight_ideal
    fit, _ = Rotation.align_vectors(b[inliers], a / np.linalg.norm(a, axis=1, keepdims=True))
    return fit.as_matrix(), int(inliers.sum())


@pytest.mark.parametrize("fmt", FORMATS)
def test_truth_agrees_with_the_images(flight, ideal, fmt):
    T_wf, T_wi = WORLD_CAM[fmt](flight["out"]), WORLD_CAM[fmt](ideal["out"])
    T_fi = se3_inv(T_wf) @ T_wi  # ideal camera -> flight camera, by the exported truth
    R_img, n = image_rotation(flight["out"], ideal["out"], T_fi[:3, 3])
    T_wf_physical = flight["truth"].as_matrix() @ flight["physical"]
    exported_deg = angle_deg(R_img, T_fi)
    physical_deg = angle_deg(R_img, se3_inv(T_wf_physical) @ T_wi)
    print(
        f"\n{fmt}: image fit ({n} points) vs exported truth {exported_deg:.4f} deg; vs the physical camera "
        f"{physical_deg:.4f} deg; exported rotation {1e3 * Rotation.from_matrix(T_fi[:3, :3]).as_rotvec()} mrad"
    )
    assert n > 200
    assert exported_deg <= TOL_DEG
    assert physical_deg > 3 * TOL_DEG


# --------------------------------------------------------------------------------------- Kalibr / OpenVINS
def kalibr_yaml(path: Path) -> dict:
    from ruamel.yaml import YAML

    text = path.read_text()
    return YAML(typ="safe").load(text.removeprefix("%YAML:1.0\n"))  # OpenCV's header is not YAML 1.2


def pixel(K: np.ndarray, T_cam_world: np.ndarray, p_world: np.ndarray) -> np.ndarray:
    p = T_cam_world[:3, :3] @ p_world + T_cam_world[:3, 3]
    return np.array([K[0, 0] * p[0] / p[2] + K[0, 2], K[1, 1] * p[1] / p[2] + K[1, 2]])


def intrinsics_K(values: list[float]) -> np.ndarray:
    fu, fv, pu, pv = values
    return np.array([[fu, 0.0, pu], [0.0, fv, pv], [0.0, 0.0, 1.0]])


def test_kalibr_and_openvins_reproject_like_the_exported_camera_model(flight):
    out = flight["out"]
    for name in (CAMCHAIN, IMU, OPENVINS_CAMCHAIN, OPENVINS_IMU):
        assert (out / name).is_file(), name
    chain, ov = kalibr_yaml(out / CAMCHAIN), kalibr_yaml(out / OPENVINS_CAMCHAIN)
    T_world_rover = euroc_truth_rover(out, first_frame_t_s(out))  # the exported truth at the first frame
    T_rover_world = se3_inv(T_world_rover)
    T_world_cam0 = euroc_world_cam(out)
    p_world = (T_world_cam0 @ np.array([0.4, -0.3, 3.0, 1.0]))[:3]  # a point 3 m in front of the left camera
    seq = out / "sequences" / "00"
    calib = {k: np.array(v.split(), float) for k, v in (ln.split(":", 1) for ln in (seq / "calib.txt").open())}
    P0, P1, Tr = (np.vstack([calib[k].reshape(3, 4), [0, 0, 0, 1]]) for k in ("P0", "P1", "Tr"))
    kitti0 = P0 @ Tr @ T_rover_world @ np.append(p_world, 1.0)
    kitti1 = P1 @ Tr @ T_rover_world @ np.append(p_world, 1.0)
    kitti = [kitti0[:2] / kitti0[2], kitti1[:2] / kitti1[2]]
    T_c0_imu = np.array(chain["cam0"]["T_cam_imu"])
    for i, cam in enumerate(("cam0", "cam1")):
        sensor = euroc_sensor(out, cam)
        euroc = pixel(intrinsics_K(sensor["intrinsics"]), se3_inv(np.array(sensor["T_BS"]["data"]).reshape(4, 4))
                      @ T_rover_world, p_world)  # fmt: skip
        K = intrinsics_K(chain[cam]["intrinsics"])
        assert chain[cam]["resolution"] == sensor["resolution"] and chain[cam]["camera_model"] == "pinhole"
        assert chain[cam]["distortion_model"] == "radtan" and chain[cam]["distortion_coeffs"] == [0.0] * 4
        assert chain[cam]["timeshift_cam_imu"] == 0.0
        via_kalibr = pixel(K, np.array(chain[cam]["T_cam_imu"]) @ T_rover_world, p_world)
        via_openvins = pixel(intrinsics_K(ov[cam]["intrinsics"]), se3_inv(np.array(ov[cam]["T_imu_cam"]))
                             @ T_rover_world, p_world)  # fmt: skip
        pixels = {"kalibr": via_kalibr, "openvins": via_openvins}
        if i == 1:
            pixels["kalibr T_cn_cnm1"] = pixel(K, np.array(chain["cam1"]["T_cn_cnm1"]) @ T_c0_imu @ T_rover_world,
                                               p_world)  # fmt: skip
        for how, uv in pixels.items():
            assert np.abs(uv - euroc).max() <= 0.01, (cam, how, uv, euroc)
        gaps = ", ".join(f"{k} {np.abs(v - euroc).max():.1e} px" for k, v in pixels.items())
        print(f"\n{cam}: EuRoC {euroc}, {gaps}")
        assert 0 < euroc[0] < K[0, 2] * 2 and 0 < euroc[1] < K[1, 2] * 2
        if i == 0:  # KITTI's P0 and Tr: the same left camera
            assert np.abs(kitti[0] - euroc).max() <= 0.01
        else:  # KITTI's P1 is the rectified rig (baseline along x): the true right camera differs by a few px/1000
            assert np.abs(kitti[1] - euroc).max() < 1.0
    np.testing.assert_allclose(np.array(ov["cam0"]["T_imu_cam"]) @ T_c0_imu, np.eye(4), atol=1e-9)  # the inverse


def test_imu_noise_in_kalibr_units(flight):
    from rover_sim.sim.sensors import ImuParams

    p = ImuParams()  # the defaults the flight profile flies (LN-200 class)
    imu, ov = kalibr_yaml(flight["out"] / IMU), kalibr_yaml(flight["out"] / OPENVINS_IMU)["imu0"]
    expected = {
        "gyroscope_noise_density": p.gyro_arw_deg_sqrt_h * math.pi / 180.0 / 60.0,  # deg/sqrt(h) -> rad/s/sqrt(Hz)
        "accelerometer_noise_density": p.accel_noise_ug_sqrt_hz * 1e-6 * 9.80665,  # ug/sqrt(Hz) -> m/s^2/sqrt(Hz)
        "gyroscope_random_walk": p.gyro_bias_instability_deg_h
        * math.pi
        / 180.0
        / 3600.0
        * math.sqrt(2.0 / p.gyro_bias_corr_time_s),  # Gauss-Markov sigma sqrt(2/tau): rad/s^2/sqrt(Hz)
        "accelerometer_random_walk": 0.0,
        "update_rate": p.rate_hz,
    }
    for key, value in expected.items():
        assert imu[key] == pytest.approx(value, rel=1e-5, abs=1e-12), key
        assert ov[key] == pytest.approx(value, rel=1e-5, abs=1e-12), key
    assert imu["rostopic"] == ov["rostopic"] == "/imu0" and ov["model"] == "kalibr"
    np.testing.assert_array_equal(np.array(ov["T_i_b"]), np.eye(4))


def test_openvins_needs_euroc(tmp_path):
    from typer.testing import CliRunner

    from rover_sim.cli.main import app

    r = CliRunner().invoke(app, ["export", "wopmay", "--format", "kitti", "--openvins", "--out", str(tmp_path / "x")])
    assert r.exit_code == 2 and "--openvins" in r.stderr and "--format euroc" in r.stderr, r.output
    assert not (tmp_path / "x").exists()
