"""Flight-profile pairs for ``bench stereo``: raw (distorted, CCD-formed) hazcam pairs rectified onboard.

Each pair is rendered through the run's *true* lenses (:class:`~rover_sim.render.lens.TrueLens`, mounting rotation
included) and the flight image formation, then rectified with the *onboard* calibration (seeded calibration errors,
:class:`~rover_sim.world.calibration.RunCalibration`), exactly what the onboard stack gets in the flight profile.

Ground truth in the rectified frame follows the true correspondence, not the onboard belief: each scored 3D point
(from the ideal depth render of the left MJCF camera) is projected through the true raw camera of each side, then
carried into that side's rectified image through the onboard model (the inverse of the rectification table).
``gt = u_left_rect - u_right_rect``, splatted to the nearest left pixel with the nearest point winning. A matcher
that finds the true correspondence therefore scores 0 px error, whatever the calibration error; the residual row
offset of the true correspondence (the calibration's epipolar error) is what the matcher must tolerate.
"""

from __future__ import annotations

import numpy as np

from nav.camera import PinholeCamera
from nav.lens import CameraModel
from nav.rectify import StereoCalibration, rectification
from rover_sim.render.cameras import camera_model
from rover_sim.render.config import RenderConfig
from rover_sim.render.imaging import ImagingSpec
from rover_sim.render.renderer import StereoRenderer
from rover_sim.scenario.lens_spec import LensErrorSpec
from rover_sim.world.calibration import RunCalibration, build_true_lens

FLIGHT_SEED_OFFSET = 1000  # calibration draws independent of the terrain seeds


def _rect_uv(points_rover: np.ndarray, true: CameraModel, onboard: CameraModel, rect: PinholeCamera) -> np.ndarray:
    """Rectified pixel of each rover-frame point: true raw projection, then the onboard ray into the rectified
    camera (what the rectification table does, inverted)."""
    T = true.T_rover_cam
    p_cam = (points_rover - T[:3, 3]) @ T[:3, :3]
    uv_raw = true.project(p_cam)
    rays = onboard.unproject(uv_raw)
    R_rect_raw = rect.T_rover_cam[:3, :3].T @ onboard.T_rover_cam[:3, :3]
    r = rays @ R_rect_raw.T
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.stack([rect.fx_px * r[:, 0] / r[:, 2] + rect.cx_px, rect.fy_px * r[:, 1] / r[:, 2] + rect.cy_px], 1)


def rectified_ground_truth(
    depth_m: np.ndarray, scored: np.ndarray, pin_left: PinholeCamera, true_l: CameraModel, true_r: CameraModel,
    onboard_l: CameraModel, onboard_r: CameraModel, rect_left: PinholeCamera,
) -> np.ndarray:  # fmt: skip
    """Ground-truth disparity (rectified left pixels; NaN unscored) of the depth render of ``pin_left``."""
    v, u = np.nonzero(scored & np.isfinite(depth_m))
    z = depth_m[v, u]
    p_cam = np.stack([(u - pin_left.cx_px) / pin_left.fx_px * z, (v - pin_left.cy_px) / pin_left.fy_px * z, z], 1)
    p_rover = p_cam @ pin_left.T_rover_cam[:3, :3].T + pin_left.T_rover_cam[:3, 3]
    uv_l = _rect_uv(p_rover, true_l, onboard_l, rect_left)
    uv_r = _rect_uv(p_rover, true_r, onboard_r, rect_left)  # same intrinsics and rows as the right rectified camera
    disp = uv_l[:, 0] - uv_r[:, 0]
    h, w = depth_m.shape
    iu, iv = np.rint(uv_l[:, 0]), np.rint(uv_l[:, 1])
    ok = np.isfinite(disp) & (iu >= 0) & (iu < w) & (iv >= 0) & (iv < h)
    gt = np.full((h, w), np.nan, dtype=np.float32)
    order = np.argsort(-z[ok])  # far first: the nearest point is written last and wins
    gt[iv[ok][order].astype(int), iu[ok][order].astype(int)] = disp[ok][order]
    return gt


def render_flight_pair(sim, pair: str, resolution_px: int, seed: int, scored_fn):  # noqa: ANN001, ANN201
    """(left_rect, right_rect, gt, rig) of ``pair`` in the flight profile; ``scored_fn(renderer, pair)`` gives the
    (depth, scored mask) of the left MJCF camera rendered at ``resolution_px``."""
    lens_spec = LensErrorSpec(**LensErrorSpec.profile_defaults("flight"))
    calib = RunCalibration(lens_spec, seed + FLIGHT_SEED_OFFSET)
    config = RenderConfig(
        resolution_px=resolution_px,
        imaging=ImagingSpec(**ImagingSpec.profile_defaults("flight")),
        imaging_seed=seed,
    )
    with StereoRenderer(sim, config, lens=build_true_lens(sim.model, sim.data, calib, config.native_px)) as r:
        pins = [
            camera_model(sim.model, sim.data, f"{pair}_{s}", resolution_px, resolution_px) for s in ("left", "right")
        ]
        onboard = [calib.onboard_model(p) for p in pins]
        true = [calib.true_model(p) for p in pins]
        rect = rectification(StereoCalibration(onboard[0], onboard[1], pins[0]))
        frame = r.render_pair(pair)
        left, right = rect.apply(frame.left, frame.right)
        depth, scored = scored_fn(r, pair)
    gt = rectified_ground_truth(depth, scored, pins[0], true[0], true[1], onboard[0], onboard[1], rect.rig.left)
    return left, right, gt, rect.rig
