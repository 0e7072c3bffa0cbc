"""Per-run truth and calibration of the cameras, and the mast encoders (``[sensors.lens]``).

One seeded draw per run (stream ``LENS_SEED_STREAM`` of the scenario seed) gives, per stereo pair:

* the true mounting rotation of each camera relative to its MJCF camera (build tolerance; the true raw camera the
  renderer images through, :mod:`rover_sim.render.lens`);
* the calibration errors: a rotation common to the pair, the right camera's rotation and position relative to the
  left, a principal-point error common to the pair (a relative principal-point offset is indistinguishable from a
  relative rotation, which the stereo calibration's epipolar constraint pins down: ``stereo_rotation_deg``), and
  per camera focal length and distortion-coefficient errors.

The onboard model of a camera is the true model (lens, mounting) at the **commanded** mast pointing with these
errors applied. :class:`MastEncoders` draws, per repointing, where the mast truly stops (resolution + backlash).
Sizes and sources: :mod:`rover_sim.scenario.lens_spec`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from nav.camera import PinholeCamera, StereoRig
from nav.lens import CahvorCamera, CameraModel, FisheyeCamera
from nav.rectify import StereoCalibration, rectification
from rover_sim.render.cameras import STEREO_PAIRS, camera_model
from rover_sim.render.lens import nominal_model, with_rotation
from rover_sim.scenario.lens_spec import LensErrorSpec

LENS_SEED_STREAM = 16_001  # independent of the other seeded streams of a scenario
MAST_SEED_STREAM = 16_002
FULL_RES_PX = 1024  # principal-point errors are given in full-resolution pixels


@dataclass(frozen=True)
class CameraErrors:
    """Calibration error of one camera: extrinsic (in its own frame), focal scale, principal point (full-res px),
    relative distortion-coefficient error."""

    rotation_rad: np.ndarray
    position_m: np.ndarray
    focal_scale: float
    principal_px: np.ndarray
    distortion_scale: np.ndarray


def _rot(rotvec: np.ndarray) -> np.ndarray:
    return Rotation.from_rotvec(rotvec).as_matrix()


class RunCalibration:
    """The seeded true mounting rotations and calibration errors of every camera for one run."""

    def __init__(self, spec: LensErrorSpec, seed: int) -> None:
        self.spec = spec
        rng = np.random.default_rng([int(seed), LENS_SEED_STREAM])
        d2r = math.radians
        self.mount: dict[str, np.ndarray] = {}
        self.errors: dict[str, CameraErrors] = {}
        for pair in STEREO_PAIRS:
            common = rng.normal(0.0, d2r(spec.camera_rotation_deg), 3)
            relative = rng.normal(0.0, d2r(spec.stereo_rotation_deg), 3)
            baseline = rng.normal(0.0, spec.baseline_mm * 1e-3, 3)
            principal = rng.normal(0.0, spec.principal_point_px, 2)  # common: the relative part is a rotation
            for side in ("left", "right"):
                name = f"{pair}_{side}"
                self.mount[name] = _rot(rng.normal(0.0, d2r(spec.mount_rotation_deg), 3))
                rot = (
                    common
                    if side == "left"
                    else (Rotation.from_rotvec(relative) * Rotation.from_rotvec(common)).as_rotvec()
                )
                self.errors[name] = CameraErrors(
                    rotation_rad=rot,
                    position_m=np.zeros(3) if side == "left" else baseline,
                    focal_scale=1.0 + rng.normal(0.0, spec.focal_length_pct / 100.0),
                    principal_px=principal,
                    distortion_scale=1.0 + rng.normal(0.0, spec.distortion_residual_pct / 100.0, 4),
                )

    def true_model(self, pinhole: PinholeCamera) -> CameraModel:
        """The true raw camera for ``pinhole`` (MJCF camera, any size): the lens design with ``T_rover_cam`` =
        ``pinhole.T_rover_cam`` turned by the mounting rotation."""
        model = nominal_model(pinhole, self.spec.navcam_r, self.spec.hazcam_k)
        T = np.asarray(pinhole.T_rover_cam, dtype=float).copy()
        T[:3, :3] = T[:3, :3] @ self.mount[pinhole.name]
        return replace(model, T_rover_cam=T)  # type: ignore[type-var]

    def render_model(self, pinhole: PinholeCamera) -> CameraModel:
        """The true raw camera with only its mounting rotation as ``T_rover_cam`` (relative to the MJCF camera)."""
        nominal = nominal_model(pinhole, self.spec.navcam_r, self.spec.hazcam_k)
        return with_rotation(nominal, self.mount[pinhole.name])

    def onboard_model(self, pinhole: PinholeCamera) -> CameraModel:
        """What the calibration says the camera is (``pinhole``: the MJCF camera at the commanded pointing)."""
        true = self.true_model(pinhole)
        e = self.errors[pinhole.name]
        dT = np.eye(4)
        dT[:3, :3], dT[:3, 3] = _rot(e.rotation_rad), e.position_m
        pp = e.principal_px * pinhole.width_px / FULL_RES_PX
        changes: dict = {
            "T_rover_cam": true.T_rover_cam @ dT,
            "fx_px": true.fx_px * e.focal_scale,
            "fy_px": true.fy_px * e.focal_scale,
            "cx_px": true.cx_px + pp[0],
            "cy_px": true.cy_px + pp[1],
        }
        if isinstance(true, CahvorCamera):
            changes["r"] = tuple(float(c * s) for c, s in zip(true.r, e.distortion_scale[:3], strict=True))
        elif isinstance(true, FisheyeCamera):
            changes["k"] = tuple(float(c * s) for c, s in zip(true.k, e.distortion_scale, strict=True))
        return replace(true, **changes)  # type: ignore[type-var]


class MastEncoders:
    """Where the mast truly stops: the command plus a seeded error within the encoder resolution and backlash.

    Per axis: ``U(-res/2, res/2)`` (quantisation) minus ``U(0, backlash)`` in the direction of motion (the gear
    train stops short). Zero errors give the command exactly.
    """

    def __init__(self, spec: LensErrorSpec, seed: int) -> None:
        self.res, self.backlash = spec.mast_resolution_deg, spec.mast_backlash_deg
        self._rng = np.random.default_rng([int(seed), MAST_SEED_STREAM])
        self._last = np.zeros(2)
        self.last_error_deg = np.zeros(2)  # (pan, elevation) error of the latest repointing (truth: evaluator only)

    def true_angles_deg(self, pan_deg: float, elevation_deg: float) -> tuple[float, float]:
        cmd = np.array([pan_deg, elevation_deg], dtype=float)
        if self.res == 0.0 and self.backlash == 0.0:
            return float(cmd[0]), float(cmd[1])
        direction = np.sign(cmd - self._last)
        self._last = cmd
        err = self._rng.uniform(-0.5, 0.5, 2) * self.res - direction * self._rng.uniform(0.0, 1.0, 2) * self.backlash
        self.last_error_deg = err
        return float(cmd[0] + err[0]), float(cmd[1] + err[1])


def cameras_at_pointing(
    model: mujoco.MjModel, data: mujoco.MjData, names: list[str], px: int, pan_deg: float, elevation_deg: float
) -> list[PinholeCamera]:
    """MJCF pinhole cameras ``names`` at ``px`` with the mast at the given pointing (the rest of ``data``'s state
    unchanged): the extrinsics flight software computes from the commanded angles."""
    scratch = mujoco.MjData(model)
    scratch.qpos[:] = data.qpos
    scratch.qpos[model.joint("mast_pan").qposadr[0]] = math.radians(pan_deg)
    scratch.qpos[model.joint("mast_tilt").qposadr[0]] = -math.radians(elevation_deg)  # the tilt joint turns down
    mujoco.mj_kinematics(model, scratch)
    mujoco.mj_camlight(model, scratch)
    return [camera_model(model, scratch, n, px, px) for n in names]


def onboard_stereo_models(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    calibration: RunCalibration | None,
    camera: str,
    px: int,
    pan_deg: float,
    elevation_deg: float,
) -> tuple[StereoRig, StereoCalibration | None]:
    """What flight software holds for ``camera``'s pair at ``px`` and the *commanded* mast pointing: without lens
    errors (``calibration`` None) the exact pinhole rig there (only the mast encoders err); with them the calibrated
    raw models and the rectified rig they define (what :meth:`~rover_sim.runtime.onboard.Onboard.rectified` uses)."""
    names = [f"{camera}_left", f"{camera}_right"]
    pins = cameras_at_pointing(model, data, names, px, pan_deg, elevation_deg)
    if calibration is None:
        return StereoRig(pins[0], pins[1]), None
    calib = StereoCalibration(calibration.onboard_model(pins[0]), calibration.onboard_model(pins[1]), target=pins[0])
    return rectification(calib).rig, calib


def build_true_lens(  # noqa: ANN201
    model: mujoco.MjModel,
    data: mujoco.MjData,
    calibration: RunCalibration,
    native_px: int,
    pairs: tuple[str, ...] = STEREO_PAIRS,
    render_oversample: float | None = None,
):
    """The renderer's :class:`~rover_sim.render.lens.TrueLens` for the cameras of ``pairs`` at ``native_px``
    (``render_oversample``: replaces the spec's, e.g. for the rock survey's panoramas)."""
    from rover_sim.render.lens import TrueLens

    names = [f"{p}_{s}" for p in pairs for s in ("left", "right")]
    models = {n: calibration.render_model(camera_model(model, data, n, native_px, native_px)) for n in names}
    spec = calibration.spec
    oversample = spec.render_oversample if render_oversample is None else render_oversample
    return TrueLens(models, oversample, spec.hazcam_max_off_axis_deg)


def render_rectified(renderer, calibration: RunCalibration, pair: str) -> tuple[np.ndarray, np.ndarray, StereoRig]:  # noqa: ANN001
    """Render ``pair`` raw (``renderer`` built with this calibration's true lens, :func:`build_true_lens`) and
    rectify it with the onboard models at the mast's current state: flight-profile pairs for benchmarks that run
    outside a :class:`~rover_sim.world.world.World` (e.g. ``bench stereo``). Returns (left, right, rig)."""
    px = renderer.config.resolution_px
    pins = [camera_model(renderer.sim.model, renderer.sim.data, f"{pair}_{s}", px, px) for s in ("left", "right")]
    calib = StereoCalibration(calibration.onboard_model(pins[0]), calibration.onboard_model(pins[1]), pins[0])
    rect = rectification(calib)
    frame = renderer.render_pair(pair)
    left, right = rect.apply(frame.left, frame.right)
    return left, right, rect.rig
