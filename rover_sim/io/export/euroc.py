"""EuRoC MAV (ASL) layout, as read by VINS-Fusion, OKVIS, ORB-SLAM3 (``stereo_inertial_euroc``), Kalibr tools.

::

    OUT/mav0/cam0/data/<t_ns>.png, data.csv, sensor.yaml     left (rectified greyscale), intrinsics, T_BS
    OUT/mav0/cam1/...                                        right
    OUT/mav0/imu0/data.csv, sensor.yaml                      gyro (rad/s) and accel (m/s^2), rover frame
    OUT/mav0/wheels0/data.csv, sensor.yaml                   wheel spin and steering angles (rad), commanded mast
    OUT/mav0/state_groundtruth_estimate0/data.csv            true rover pose p_RS_R, q_RS (w first), velocity by
                                                             central differences; biases written as 0
    OUT/camchain-imucam.yaml, OUT/imu.yaml                   Kalibr camera-IMU chain and IMU noise
    OUT/kalibr_imucam_chain.yaml, kalibr_imu_chain.yaml      the same for OpenVINS (T_imu_cam), with ``openvins``

The body frame B is the rover frame, which is also the IMU frame (``imu0`` has T_BS = identity). ``T_BS`` of a
camera is its pose on the rover (``p_B = T_BS p_S``, as in EuRoC), taken at the first frame (the navcam moves
with the mast: re-pointing it mid-run is not reflected): the true pose of the *rectified* camera the images are
in (:mod:`rover_sim.io.export.camera_truth`); cam0's ``T_BS_physical_camera`` is the physical camera's, for
reference. The images are rectified: ``distortion_coefficients`` are zero. R, the ground-truth reference frame,
is the simulator's world (x east, y north, z up). The Kalibr/OpenVINS files: :mod:`rover_sim.io.export.kalibr`.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from nav.trajectory import Pose
from nav.types import EncoderSample, ImuSample
from rover_sim.io.export.base import MAST_JOINTS, STEER_JOINTS, WHEEL_JOINTS, DatasetWriter, ExportMeta, Frame, t_ns
from rover_sim.io.export.kalibr import gyro_random_walk, write_calibration

GT_HEADER = (
    "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
    "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], "
    "b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]"
)
IMU_HEADER = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)


def comment(text: str) -> str:
    return f"comment: {json.dumps(text)}\n"  # a JSON string is a valid YAML double-quoted scalar


def matrix_yaml(name: str, T: np.ndarray) -> str:
    rows = [", ".join(f"{v:.12f}" for v in r) for r in np.asarray(T, dtype=float)]
    body = ",\n         ".join(rows)
    return f"{name}:\n  cols: 4\n  rows: 4\n  data: [{body}]\n"


class EurocWriter(DatasetWriter):
    name = "euroc"

    def __init__(self, out: Path, openvins: bool = False) -> None:
        self.root, self.openvins = Path(out), openvins
        self.mav = self.root / "mav0"
        self.meta: ExportMeta | None = None
        dirs = ("cam0/data", "cam1/data", "imu0", "wheels0", "state_groundtruth_estimate0")
        for d in dirs:
            (self.mav / d).mkdir(parents=True, exist_ok=True)
        self.cam_csv = [open(self.mav / c / "data.csv", "w") for c in ("cam0", "cam1")]
        for f in self.cam_csv:
            f.write("#timestamp [ns],filename\n")
        self.imu_csv = open(self.mav / "imu0" / "data.csv", "w")
        self.imu_csv.write(IMU_HEADER + "\n")
        self.wheels_csv = open(self.mav / "wheels0" / "data.csv", "w")
        cols = [f"{j} [rad]" for j in WHEEL_JOINTS + STEER_JOINTS + MAST_JOINTS]
        self.wheels_csv.write("#timestamp [ns]," + ",".join(cols) + "\n")
        self.gt_csv = open(self.mav / "state_groundtruth_estimate0" / "data.csv", "w")
        self.gt_csv.write(GT_HEADER + "\n")
        self.first_frame: Frame | None = None
        self.frame_t: list[float] = []
        self.gt_prev: Pose | None = None
        self.gt_cur: Pose | None = None

    def start(self, meta: ExportMeta) -> None:
        self.meta = meta

    def frame(self, frame: Frame) -> None:
        ns = t_ns(frame.t_s)
        for i, image in enumerate((frame.left_u8, frame.right_u8)):
            cv2.imwrite(str(self.mav / f"cam{i}" / "data" / f"{ns}.png"), image)
            self.cam_csv[i].write(f"{ns},{ns}.png\n")
        if self.first_frame is None:
            self.first_frame = frame
        self.frame_t.append(frame.t_s)

    def imu(self, sample: ImuSample) -> None:
        g, a = sample.gyro_rad_s, sample.accel_m_s2
        self.imu_csv.write(f"{t_ns(sample.t_s)},{g[0]:.9e},{g[1]:.9e},{g[2]:.9e},{a[0]:.9e},{a[1]:.9e},{a[2]:.9e}\n")

    def encoders(self, sample: EncoderSample, mast_pan_rad: float, mast_elevation_rad: float) -> None:
        vals = np.concatenate([sample.wheel_angle_rad, sample.steer_angle_rad, [mast_pan_rad, mast_elevation_rad]])
        self.wheels_csv.write(f"{t_ns(sample.t_s)}," + ",".join(f"{v:.9e}" for v in vals) + "\n")

    def truth(self, pose: Pose) -> None:
        """Written one pose late: the velocity is the central difference of its neighbours."""
        if self.gt_cur is not None:
            self.write_gt(self.gt_cur, self.gt_prev or self.gt_cur, pose)
        self.gt_prev, self.gt_cur = self.gt_cur, pose

    def write_gt(self, pose: Pose, before: Pose, after: Pose) -> None:
        dt = after.t_s - before.t_s
        v = (after.position_xyz_m - before.position_xyz_m) / dt if dt > 0 else np.zeros(3)
        vals = np.concatenate([pose.position_xyz_m, pose.quat_wxyz, v, np.zeros(6)])
        self.gt_csv.write(f"{t_ns(pose.t_s)}," + ",".join(f"{x:.9f}" for x in vals) + "\n")

    def close(self) -> None:
        if self.gt_cur is not None:
            self.write_gt(self.gt_cur, self.gt_prev or self.gt_cur, self.gt_cur)
        for f in (*self.cam_csv, self.imu_csv, self.wheels_csv, self.gt_csv):
            f.close()
        self.write_yaml()

    def write_yaml(self) -> None:
        meta = self.meta or ExportMeta("", 0, "", "")
        gyro_walk = gyro_random_walk(meta)
        imu = (
            "sensor_type: imu\n"
            + comment("rover IMU (LN-200 class); body frame = rover frame (x forward, y left, z up)")
            + matrix_yaml("T_BS", np.eye(4))
            + f"rate_hz: {meta.imu_rate_hz:g}\n"
            + f"gyroscope_noise_density: {meta.gyro_noise_density:.6e}  # rad/s/sqrt(Hz)\n"
            + f"accelerometer_noise_density: {meta.accel_noise_density:.6e}  # m/s^2/sqrt(Hz)\n"
            + f"gyroscope_random_walk: {gyro_walk:.6e}"
            + "  # rad/s^2/sqrt(Hz): the Gauss-Markov bias instability as a random walk\n"
            + "accelerometer_random_walk: 0.0\n"
        )
        (self.mav / "imu0" / "sensor.yaml").write_text(imu)
        wheels = (
            "sensor_type: encoders\n"
            + comment("wheel spin (cumulative, forward rolling +), steering (left +) and the commanded mast pan "
                      "(left +) / elevation (up +), radians")
            + f"rate_hz: {meta.encoder_rate_hz:g}\n"
            + "joints: [" + ", ".join(WHEEL_JOINTS + STEER_JOINTS + MAST_JOINTS) + "]\n"
        )  # fmt: skip
        (self.mav / "wheels0" / "sensor.yaml").write_text(wheels)
        f = self.first_frame
        write_calibration(self.root, f, meta, self.openvins)
        if f is None:
            return
        span = self.frame_t[-1] - self.frame_t[0]
        rate = (len(self.frame_t) - 1) / span if span > 0 else 0.0
        cam = f.rig.left
        for i, T in enumerate((f.T_rover_cam, f.T_rover_right_cam)):
            text = (
                "sensor_type: camera\n"
                + comment(
                    f"{f.camera} {'left' if i == 0 else 'right'}, rectified greyscale (frames: {meta.mode}; "
                    "rate_hz is the mean rate); T_BS: the true pose of the rectified camera the images are in"
                )
                + matrix_yaml("T_BS", T)
                + (matrix_yaml("T_BS_physical_camera", f.T_rover_cam_physical) if i == 0 else "")
                + f"rate_hz: {rate:.4f}\nresolution: [{cam.width_px}, {cam.height_px}]\ncamera_model: pinhole\n"
                + f"intrinsics: [{cam.fx_px:.9f}, {cam.fy_px:.9f}, {cam.cx_px:.9f}, {cam.cy_px:.9f}]"
                + "  # fu, fv, cu, cv\n"
                + "distortion_model: radial-tangential\ndistortion_coefficients: [0.0, 0.0, 0.0, 0.0]\n"
                + f"baseline_m: {f.rig.baseline_m:.9f}\n"
            )
            (self.mav / f"cam{i}" / "sensor.yaml").write_text(text)
