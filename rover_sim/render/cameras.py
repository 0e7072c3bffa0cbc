"""Camera models of the simulated rover's cameras, exported in the navigation stack's conventions.

MuJoCo cameras look along their local -z axis with +y up; :mod:`nav.camera` uses the OpenCV frame (x right, y
down, z forward). The two differ by a half turn about x: ``R_cv = R_mj @ diag(1, -1, -1)``.

Intrinsics come from the MJCF ``fovy`` with square pixels and the principal point at the image centre, exactly
what MuJoCo's renderer uses (``PinholeCamera.from_fov``). Extrinsics ``T_rover_cam`` are the camera pose in the
``rover`` body frame, read from the current ``MjData``: the navcams ride on the pan/tilt mast, so their
extrinsics change with ``mast_pan``/``mast_tilt`` and must be re-read after the mast moves (``mj_forward`` or a
physics step must have run since).
"""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np

from nav.camera import PinholeCamera, StereoRig

#: Stereo pairs of the MER-class rover: ``<pair>_left`` / ``<pair>_right`` cameras in models/mer/rover.xml.
STEREO_PAIRS: tuple[str, ...] = ("navcam", "hazcam_front", "hazcam_rear")
ROVER_BODY = "rover"
MJ_TO_CV = np.diag([1.0, -1.0, -1.0])  # MuJoCo camera axes (x right, y up, -z forward) -> OpenCV axes
RECTIFIED_ROTATION_TOL = 1e-6  # max |R_left - R_right| element of a rectified pair
RECTIFIED_OFFSET_TOL_M = 1e-6  # max off-axis component of the right camera's offset in the left frame


class StereoRigNotRectified(ValueError):
    """The two cameras of a pair differ in orientation or are not offset purely along the camera x axis.

    Fix the camera ``pos``/``xyaxes`` in models/mer/rover.xml so both share ``xyaxes`` and differ only along
    the camera x axis (the rover's lateral axis for these rigs).
    """


def camera_world_pose(model: mujoco.MjModel, data: mujoco.MjData, cam_name: str) -> np.ndarray:
    """4x4 pose of camera ``cam_name`` in the world, OpenCV axes (``p_world = T @ [p_cam, 1]``)."""
    cam = model.camera(cam_name)
    T = np.eye(4)
    T[:3, :3] = data.cam_xmat[cam.id].reshape(3, 3) @ MJ_TO_CV
    T[:3, 3] = data.cam_xpos[cam.id]
    return T


def rover_world_pose(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """4x4 pose of the ``rover`` body frame in the world."""
    body = model.body(ROVER_BODY)
    T = np.eye(4)
    T[:3, :3] = data.xmat[body.id].reshape(3, 3)
    T[:3, 3] = data.xpos[body.id]
    return T


def camera_model(
    model: mujoco.MjModel, data: mujoco.MjData, cam_name: str, width_px: int, height_px: int
) -> PinholeCamera:
    """Pinhole model of MuJoCo camera ``cam_name`` rendered at ``width_px`` x ``height_px``.

    ``fovy`` is the vertical field of view (MuJoCo convention), pixels are square, the principal point is the
    image centre. ``T_rover_cam`` is computed from ``data`` (current mast angles and all).
    """
    cam = model.camera(cam_name)
    T_world_rover = rover_world_pose(model, data)
    T_rover_cam = np.linalg.inv(T_world_rover) @ camera_world_pose(model, data, cam_name)
    return PinholeCamera.from_fov(cam_name, width_px, height_px, float(model.cam_fovy[cam.id]), T_rover_cam)


def stereo_rig(model: mujoco.MjModel, data: mujoco.MjData, pair: str, resolution_px: int = 256) -> StereoRig:
    """The rectified stereo rig ``pair`` (``'navcam'``, ``'hazcam_front'`` or ``'hazcam_rear'``), square images.

    The MJCF pairs are rectified by construction: both cameras of a pair share ``xyaxes`` and ``fovy`` and sit
    apart purely along the camera x axis (hazcams 0.10 m, navcams 0.20 m), so no image warping is needed; this
    function checks it (:class:`StereoRigNotRectified` otherwise) every time the rig is built, since the
    navcam pair moves with the mast.
    """
    if pair not in STEREO_PAIRS:
        raise ValueError(f"unknown stereo pair {pair!r}; choose one of {STEREO_PAIRS}")
    left = camera_model(model, data, f"{pair}_left", resolution_px, resolution_px)
    right = camera_model(model, data, f"{pair}_right", resolution_px, resolution_px)
    check_rectified(left, right)
    return StereoRig(left, right)


def check_rectified(left: PinholeCamera, right: PinholeCamera) -> None:
    """Raise :class:`StereoRigNotRectified` unless ``right`` = ``left`` shifted along the left camera's +x."""
    if not np.allclose(left.K, right.K):
        raise StereoRigNotRectified(f"{left.name}/{right.name}: intrinsics differ")
    T_left_right = np.linalg.inv(left.T_rover_cam) @ right.T_rover_cam
    if np.abs(T_left_right[:3, :3] - np.eye(3)).max() > RECTIFIED_ROTATION_TOL:
        raise StereoRigNotRectified(f"{left.name}/{right.name}: orientations differ")
    offset = T_left_right[:3, 3]
    if np.abs(offset[1:]).max() > RECTIFIED_OFFSET_TOL_M or offset[0] <= 0.0:
        raise StereoRigNotRectified(
            f"{left.name}/{right.name}: right camera offset {offset.round(6).tolist()} m in the left camera frame "
            "is not along +x"
        )


def save_rig(rig: StereoRig, path: str | Path) -> None:
    """Write ``rig`` as JSON (``StereoRig.to_dict``: intrinsics, ``T_rover_cam`` of each camera, baseline)."""
    Path(path).write_text(json.dumps(rig.to_dict(), indent=2))


def load_rig(path: str | Path) -> StereoRig:
    """Read a rig written by :func:`save_rig`."""
    return StereoRig.from_dict(json.loads(Path(path).read_text()))
