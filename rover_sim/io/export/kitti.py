"""KITTI odometry layout (readable with ``pykitti.odometry(OUT, "00")`` and by KITTI stereo VO/SLAM tools).

::

    OUT/sequences/00/image_0/000000.png   left, rectified greyscale (uint8)
    OUT/sequences/00/image_1/000000.png   right
    OUT/sequences/00/calib.txt            P0..P3 (3x4; P1[0,3] = P3[0,3] = -fx * baseline), Tr (rover -> cam0)
    OUT/sequences/00/times.txt            one line per frame: simulation time, seconds
    OUT/sequences/00/imu.csv              t_s, gyro xyz (rad/s), accel xyz (m/s^2), rover frame, 100 Hz
    OUT/sequences/00/wheels.csv           t_s, wheel spin angles (rad, WHEELS order), steering angles (rad)
    OUT/poses/00.txt                      true left-camera pose per frame, 3x4 row-major, in the first left
                                          camera's frame (KITTI convention: T_cam0(0)_cam0(k))

There are no colour cameras: P2/P3 repeat P0/P1 so that KITTI readers find all four. ``Tr`` (velodyne -> cam0 in
KITTI) holds the rover (body/IMU) frame -> left camera transform at the first frame. "Left camera" in ``Tr`` and
``poses/`` is the camera the exported images are in: on the flight profile the true pose of the *rectified* left
camera (:mod:`rover_sim.io.export.camera_truth`), which differs from the physical navcam by the mounting,
rectifying and calibration rotations. ``times.txt`` keeps the
simulation clock (it does not restart at 0) so it lines up with ``imu.csv``, ``wheels.csv`` and ``truth.tum``.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from nav.geometry import se3_inv
from nav.types import EncoderSample, ImuSample
from rover_sim.io.export.base import STEER_JOINTS, WHEEL_JOINTS, DatasetWriter, Frame


def projection_matrices(frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """P0, P1 of the rectified pair: ``K [I | 0]`` and ``K [I | (-baseline, 0, 0)]``."""
    K = frame.rig.left.K
    P0 = np.hstack([K, np.zeros((3, 1))])
    P1 = P0.copy()
    P1[0, 3] = -K[0, 0] * frame.rig.baseline_m
    return P0, P1


def row(values) -> str:  # noqa: ANN001
    return " ".join(f"{v:.12e}" for v in np.asarray(values, dtype=float).ravel())


class KittiWriter(DatasetWriter):
    name = "kitti"

    def __init__(self, out: Path, sequence: str = "00") -> None:
        self.root = Path(out)
        self.seq = self.root / "sequences" / sequence
        for d in ("image_0", "image_1"):
            (self.seq / d).mkdir(parents=True, exist_ok=True)
        (self.root / "poses").mkdir(parents=True, exist_ok=True)
        self.times = open(self.seq / "times.txt", "w")  # closed in close()
        self.poses = open(self.root / "poses" / f"{sequence}.txt", "w")
        self.imu_csv = open(self.seq / "imu.csv", "w")
        self.imu_csv.write("t_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2\n")
        self.wheels_csv = open(self.seq / "wheels.csv", "w")
        cols = [f"{j}_rad" for j in WHEEL_JOINTS + STEER_JOINTS]
        self.wheels_csv.write("t_s," + ",".join(cols) + "\n")
        self.n = 0
        self.T_cam0_world: np.ndarray | None = None

    def frame(self, frame: Frame) -> None:
        name = f"{self.n:06d}.png"
        cv2.imwrite(str(self.seq / "image_0" / name), frame.left_u8)
        cv2.imwrite(str(self.seq / "image_1" / name), frame.right_u8)
        T_world_cam = frame.T_world_cam
        if self.T_cam0_world is None:
            self.T_cam0_world = se3_inv(T_world_cam)
            self.write_calib(frame)
        self.times.write(f"{frame.t_s:.6e}\n")
        self.poses.write(row((self.T_cam0_world @ T_world_cam)[:3, :]) + "\n")
        self.n += 1

    def write_calib(self, frame: Frame) -> None:
        P0, P1 = projection_matrices(frame)
        Tr = se3_inv(frame.T_rover_cam)[:3, :]
        lines = [f"P0: {row(P0)}", f"P1: {row(P1)}", f"P2: {row(P0)}", f"P3: {row(P1)}", f"Tr: {row(Tr)}"]
        (self.seq / "calib.txt").write_text("\n".join(lines) + "\n")

    def imu(self, sample: ImuSample) -> None:
        g, a = sample.gyro_rad_s, sample.accel_m_s2
        self.imu_csv.write(f"{sample.t_s:.6f},{g[0]:.9e},{g[1]:.9e},{g[2]:.9e},{a[0]:.9e},{a[1]:.9e},{a[2]:.9e}\n")

    def encoders(self, sample: EncoderSample, mast_pan_rad: float, mast_elevation_rad: float) -> None:
        vals = np.concatenate([sample.wheel_angle_rad, sample.steer_angle_rad])
        self.wheels_csv.write(f"{sample.t_s:.6f}," + ",".join(f"{v:.9e}" for v in vals) + "\n")

    def close(self) -> None:
        for f in (self.times, self.poses, self.imu_csv, self.wheels_csv):
            f.close()
