"""Camera-IMU calibration beside a EuRoC export, in Kalibr's layout and (optionally) OpenVINS's.

Kalibr (ethz-asl/kalibr wiki, "YAML formats" and "IMU Noise Model"):

* ``camchain-imucam.yaml``: per camera ``camera_model`` (pinhole), ``intrinsics`` ``[fu, fv, pu, pv]``,
  ``distortion_model`` / ``distortion_coeffs`` (radtan, zeros: the images are rectified), ``resolution``
  ``[width, height]``, ``T_cam_imu`` (IMU -> camera: ``p_cam = T_cam_imu p_imu``), for ``cam1`` also
  ``T_cn_cnm1`` (cam0 -> cam1), ``timeshift_cam_imu`` (``t_imu = t_cam + shift``: 0, the simulator stamps both
  on one clock), ``rostopic``, ``cam_overlaps``.
* ``imu.yaml``: ``accelerometer_noise_density`` (m/s^2/sqrt(Hz)), ``accelerometer_random_walk`` (m/s^3/sqrt(Hz)),
  ``gyroscope_noise_density`` (rad/s/sqrt(Hz)), ``gyroscope_random_walk`` (rad/s^2/sqrt(Hz)), ``update_rate``
  (Hz), ``rostopic``: Kalibr's continuous-time white noise and bias random walk.

OpenVINS (rpng/open_vins ``config/euroc_mav/``) reads the same camera fields with ``T_imu_cam`` (camera -> IMU,
the inverse of Kalibr's ``T_cam_imu``) in ``kalibr_imucam_chain.yaml``, and ``kalibr_imu_chain.yaml`` with the
noise under ``imu0`` plus its IMU intrinsics (identity here), both files starting ``%YAML:1.0`` (OpenCV).

The numbers: the IMU frame is the rover (body) frame; the cameras are the true *rectified* cameras of the first
exported frame (:mod:`rover_sim.io.export.camera_truth`: the frame the images are in), so that
``T_cam_imu`` reprojects the exported ground truth onto the exported images. The IMU noise converts the LN-200
model of :class:`rover_sim.sim.sensors.ImuParams`: its white noise densities are Kalibr's noise densities as they
are; its gyro bias, a first-order Gauss-Markov process of stationary sigma ``s`` and correlation time ``tau``,
drifts over short times like a random walk of density ``s * sqrt(2 / tau)``; its accelerometer bias is constant
over a run (a random walk of 0). The IMU's axis misalignment and scale errors (flight profile) are not written.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from nav.geometry import se3_inv
from rover_sim.io.export.base import ExportMeta, Frame

CAMCHAIN = "camchain-imucam.yaml"
IMU = "imu.yaml"
OPENVINS_CAMCHAIN = "kalibr_imucam_chain.yaml"
OPENVINS_IMU = "kalibr_imu_chain.yaml"
OPENCV_HEADER = "%YAML:1.0\n"  # OpenVINS reads its configuration with OpenCV's FileStorage


def gyro_random_walk(meta: ExportMeta) -> float:
    """Kalibr ``gyroscope_random_walk`` (rad/s^2/sqrt(Hz)) of the Gauss-Markov gyro bias: ``s * sqrt(2 / tau)``
    (the variance of a first-order Gauss-Markov step ``dt`` is ``s^2 (1 - exp(-2 dt / tau)) ~ s^2 2 dt / tau``)."""
    return meta.gyro_bias_sigma * math.sqrt(2.0 / max(meta.gyro_bias_corr_time_s, 1e-9))


ACCEL_RANDOM_WALK = 0.0  # m/s^3/sqrt(Hz): the model's accelerometer bias is a constant turn-on bias


def _matrix(T: np.ndarray, indent: str) -> str:
    return "".join(f"{indent}- [{', '.join(f'{v:.12f}' for v in r)}]\n" for r in np.asarray(T, dtype=float))


def _camera(frame: Frame, i: int, key: str, T: np.ndarray, indent: str = "  ") -> str:
    cam = frame.rig.left if i == 0 else frame.rig.right
    return (
        f"cam{i}:\n"
        + f"{indent}{key}:\n"
        + _matrix(T, indent + "  ")
        + f"{indent}cam_overlaps: [{1 - i}]\n"
        + f"{indent}camera_model: pinhole\n"
        + f"{indent}distortion_coeffs: [0.0, 0.0, 0.0, 0.0]\n"
        + f"{indent}distortion_model: radtan\n"
        + f"{indent}intrinsics: [{cam.fx_px:.9f}, {cam.fy_px:.9f}, {cam.cx_px:.9f}, {cam.cy_px:.9f}]"
        + "  # fu, fv, pu, pv\n"
        + f"{indent}resolution: [{cam.width_px}, {cam.height_px}]\n"
        + f"{indent}rostopic: /cam{i}/image_raw\n"
    )


def camchain_imucam(frame: Frame) -> str:
    """Kalibr ``camchain-imucam.yaml`` of the stereo pair of ``frame`` (the rover frame is the IMU frame)."""
    T_c0_i, T_c1_i = se3_inv(frame.T_rover_cam), se3_inv(frame.T_rover_right_cam)
    text = f"# {frame.camera} stereo pair, rectified images; T_cam_imu: IMU (rover) frame -> camera frame\n"
    text += _camera(frame, 0, "T_cam_imu", T_c0_i) + "  timeshift_cam_imu: 0.0\n"
    text += _camera(frame, 1, "T_cam_imu", T_c1_i) + "  timeshift_cam_imu: 0.0\n"
    text += "  T_cn_cnm1:\n" + _matrix(T_c1_i @ se3_inv(T_c0_i), "    ")
    return text


def imu_noise(meta: ExportMeta) -> str:
    """Kalibr ``imu.yaml``: the IMU model's noise in Kalibr's continuous-time terms."""
    return (
        f"# {meta.scenario} (seed {meta.seed}): the simulated IMU's error model in Kalibr's terms\n"
        f"accelerometer_noise_density: {meta.accel_noise_density:.6e}  # m/s^2/sqrt(Hz)\n"
        f"accelerometer_random_walk: {ACCEL_RANDOM_WALK:.6e}  # m/s^3/sqrt(Hz): the bias is constant over a run\n"
        f"gyroscope_noise_density: {meta.gyro_noise_density:.6e}  # rad/s/sqrt(Hz)\n"
        f"gyroscope_random_walk: {gyro_random_walk(meta):.6e}  # rad/s^2/sqrt(Hz)\n"
        "rostopic: /imu0\n"
        f"update_rate: {meta.imu_rate_hz:g}  # Hz\n"
    )


def openvins_imucam_chain(frame: Frame) -> str:
    """OpenVINS ``kalibr_imucam_chain.yaml``: as Kalibr's, with ``T_imu_cam`` (camera -> IMU) in place of
    ``T_cam_imu``."""
    text = OPENCV_HEADER + "\n"
    text += _camera(frame, 0, "T_imu_cam", frame.T_rover_cam)
    text += _camera(frame, 1, "T_imu_cam", frame.T_rover_right_cam)
    return text


def openvins_imu_chain(meta: ExportMeta) -> str:
    """OpenVINS ``kalibr_imu_chain.yaml``: the IMU noise and identity IMU intrinsics (model "kalibr")."""
    eye, zero = np.eye(3), np.zeros((3, 3))
    text = OPENCV_HEADER + "\nimu0:\n  T_i_b:\n" + _matrix(np.eye(4), "    ")
    text += (
        f"  accelerometer_noise_density: {meta.accel_noise_density:.6e}  # m/s^2/sqrt(Hz)\n"
        f"  accelerometer_random_walk: {ACCEL_RANDOM_WALK:.6e}  # m/s^3/sqrt(Hz)\n"
        f"  gyroscope_noise_density: {meta.gyro_noise_density:.6e}  # rad/s/sqrt(Hz)\n"
        f"  gyroscope_random_walk: {gyro_random_walk(meta):.6e}  # rad/s^2/sqrt(Hz)\n"
        "  rostopic: /imu0\n"
        "  time_offset: 0.0\n"
        f"  update_rate: {meta.imu_rate_hz:g}\n"
        '  model: "kalibr"\n'
    )
    for name, M in (("Tw", eye), ("R_IMUtoGYRO", eye), ("Ta", eye), ("R_IMUtoACC", eye), ("Tg", zero)):
        text += f"  {name}:\n" + _matrix(M, "    ")
    return text


def write_calibration(out: Path, frame: Frame | None, meta: ExportMeta, openvins: bool = False) -> list[Path]:
    """Write the Kalibr files (and with ``openvins`` OpenVINS's) into ``out``; the camera chain only when a frame
    was exported. Returns the paths written."""
    files = {IMU: imu_noise(meta)}
    if openvins:
        files[OPENVINS_IMU] = openvins_imu_chain(meta)
    if frame is not None:
        files[CAMCHAIN] = camchain_imucam(frame)
        if openvins:
            files[OPENVINS_CAMCHAIN] = openvins_imucam_chain(frame)
    out = Path(out)
    for name, text in files.items():
        (out / name).write_text(text)
    return [out / name for name in files]
