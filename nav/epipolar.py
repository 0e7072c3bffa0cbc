"""In-flight check of a stereo pair's epipolar alignment: the right camera's relative pitch and roll from the row
disparities of matched features, applied to the calibration before rectification.

A stereo calibration leaves a relative-rotation error between the two cameras (``sensors.lens.stereo_rotation_deg``
in the flight profile). Of its three components, two move rectified rows and are visible in every pair:
a relative **pitch** (about the baseline) shifts every right row by about ``f * pitch``, a relative **roll** (about
the optical axis) shifts them in proportion to the column. The third, toe-in (yaw), moves columns: it biases
range and is invisible in rows, so it is left alone here. Online estimation of the observable extrinsic terms from
ordinary stereo matches is standard practice (Dang, Hoffmann & Stiller 2009, "Continuous stereo self-calibration by
camera parameter tracking", IEEE TIP 18(7); Hansen, Alismail, Rander & Browning 2012, "Online continuous stereo
extrinsic parameter estimation", CVPR). MER re-checked its camera models after landing rather than in every
drive; here the check runs on the first pairs a camera takes, from the images alone.

Model (small right-camera rotation ``e`` in the rectified frame; ``x, y`` normalised rectified coordinates): a
right pixel lands at ``v_r - v_l = f * (-e_x (1 + y^2) + e_z x + e_y x y)`` (the last term, toe-in's, is below a
hundredth of a pixel at 256^2 and not fitted). :func:`fit_row_rotation` solves for ``(e_x, e_z)`` by iteratively
reweighted least squares (Huber); :func:`refine_calibration` turns the calibrated right model by ``-e``.

Optionally (``fit_scale``) the fit also takes the right camera's focal length relative to the left's: a relative
focal error ``s`` scales the rectified right image about its centre, ``v_r - v_l = f s y`` in rows and
``f s x`` in columns. Rows show it, and correcting it removes the column part, which no row test sees otherwise:
it is a disparity error growing from the image centre to ``f s`` at the edge (at 2048 px and a 0.11 % relative
error, 1.1 px at the edges: a 4 % range error at 20 m, phantom rocks in the rock survey's far field). Dang et al.
track the focal lengths beside the rotation for the same reason. Small images leave it alone: at 256^2 a 0.07 %
relative error moves rows by 0.09 px at the top and bottom edges, near the resampling's own row offsets.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from nav.camera import StereoRig
from nav.rectify import StereoCalibration

MIN_MATCHES = 100  # matched corners (pooled over pairs) before the fit is made
HUBER_PX = 0.15  # Huber threshold of the row residuals (about the corner matcher's own noise, 0.04-0.10 px)
MAX_ROTATION_RAD = 0.01  # a fitted correction beyond 0.57 deg is a mismatch, not a calibration error: refused
MAX_SCALE = 0.01  # ... and so is a relative focal length off by more than 1 %
# Row offsets the fit cannot tell from a rotation: the bilinear resampling's sub-pixel phase moves rectified rows by
# -0.04 to +0.07 px with an exact calibration (docs/physics/error-budget.md). A pair whose calibration error
# (1 sigma, ``EpipolarCheck.prior_sigma_rad``) moves its rows by less than this is not checked: there the fit would
# mostly turn that offset into a rotation (256^2 hazcams: 68 px focal length, 0.35 mrad -> 0.024 px; fitted
# "pitches" of 1.3-1.7 mrad, four sigma of the calibration, on autonav field 1)
ROW_FLOOR_PX = 0.05


@dataclass(frozen=True)
class RowFit:
    """A fitted relative rotation (rad, rectified frame: x along the baseline, z the optical axis; ``[1]`` is 0)
    and the row disparities (px, median of |v_r - v_l|) of the fitting matches before and after it.
    ``scale``: the rectified right image's magnification relative to the left's, minus one (0 unless fitted)."""

    rotation_rad: np.ndarray
    n_matches: int
    before_px: float
    after_px: float
    scale: float = 0.0


def matched_corners(
    left_u8: np.ndarray, right_u8: np.ndarray, max_corners: int = 800, fb_tol_px: float = 0.1
) -> tuple[np.ndarray, np.ndarray]:
    """(uv_left, uv_right) (N x 2, px) of Shi-Tomasi corners tracked left -> right by pyramidal Lucas-Kanade,
    kept where tracking back lands within ``fb_tol_px`` of the start and the match has positive disparity."""
    pts = cv2.goodFeaturesToTrack(left_u8, max_corners, 0.003, 5, blockSize=7)
    if pts is None or len(pts) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    fwd, st1, _ = cv2.calcOpticalFlowPyrLK(left_u8, right_u8, pts, None, winSize=(15, 15), maxLevel=3)
    back, st2, _ = cv2.calcOpticalFlowPyrLK(right_u8, left_u8, fwd, None, winSize=(15, 15), maxLevel=3)
    ok = (st1[:, 0] == 1) & (st2[:, 0] == 1) & (np.linalg.norm((back - pts)[:, 0], axis=1) < fb_tol_px)
    ok &= (pts[:, 0, 0] - fwd[:, 0, 0]) > 0.5
    return pts[ok, 0].astype(float), fwd[ok, 0].astype(float)


def row_design(uv_right: np.ndarray, rig: StereoRig, scale: bool = False) -> np.ndarray:
    """(N, 2) derivatives of the right row (px) with respect to the rotation's x and z components (rad); with
    ``scale``, (N, 3): and with respect to the right image's relative magnification."""
    cam = rig.right
    x = (uv_right[:, 0] - cam.cx_px) / cam.fx_px
    y = (uv_right[:, 1] - cam.cy_px) / cam.fy_px
    cols = [-(1.0 + y * y), x, y] if scale else [-(1.0 + y * y), x]
    return cam.fy_px * np.stack(cols, axis=1)


def fit_row_rotation(uv_left: np.ndarray, uv_right: np.ndarray, rig: StereoRig, iterations: int = 8) -> RowFit:
    """The right camera's relative pitch and roll (see the module docstring) that explain the row disparities of
    matched corners ``uv_left``/``uv_right`` (rectified px), by Huber-weighted least squares."""
    uv_left, uv_right = np.asarray(uv_left, float), np.asarray(uv_right, float)
    return fit_rows(row_design(uv_right, rig), uv_right[:, 1] - uv_left[:, 1], iterations)


def fit_rows(A: np.ndarray, dv: np.ndarray, iterations: int = 8) -> RowFit:
    """:func:`fit_row_rotation` on a design matrix (:func:`row_design`) and row disparities ``dv`` (px)."""
    if len(dv) < MIN_MATCHES:
        raise ValueError(f"{len(dv)} matched corners: the row fit needs at least {MIN_MATCHES}")
    w = np.ones(len(dv))
    p = np.zeros(A.shape[1])
    for _ in range(iterations):
        sw = np.sqrt(w)
        p = np.linalg.lstsq(A * sw[:, None], dv * sw, rcond=None)[0]
        r = np.abs(dv - A @ p)
        w = np.where(r <= HUBER_PX, 1.0, HUBER_PX / np.maximum(r, 1e-12))
    return RowFit(np.array([p[0], 0.0, p[1]]), len(dv), float(np.median(np.abs(dv))),
                  float(np.median(np.abs(dv - A @ p))), float(p[2]) if len(p) > 2 else 0.0)  # fmt: skip


def right_correction(calib: StereoCalibration, rig: StereoRig, rotation_rad: np.ndarray) -> np.ndarray:
    """3x3 rotation, in the calibrated right camera's own frame, that undoes ``rotation_rad`` (rectified frame of
    ``rig``). Both frames turn with the mast together, so the correction holds at every pointing."""
    R_cal = np.asarray(calib.right.T_rover_cam, float)[:3, :3]
    R_rect = np.asarray(rig.right.T_rover_cam, float)[:3, :3]
    undo = R_rect @ Rotation.from_rotvec(-np.asarray(rotation_rad, float)).as_matrix() @ R_rect.T
    return R_cal.T @ undo @ R_cal


def refine_calibration(calib: StereoCalibration, correction: np.ndarray, scale: float = 0.0) -> StereoCalibration:
    """``calib`` with the right model turned by ``correction`` (its own frame, :func:`right_correction`) and, for a
    fitted relative magnification ``scale`` (:class:`RowFit`), its focal lengths times ``1 + scale``: a right
    focal length calibrated too long by a factor ``1 + e`` shrinks the rectified right image by ``1 / (1 + e)``."""
    T = np.asarray(calib.right.T_rover_cam, float).copy()
    T[:3, :3] = T[:3, :3] @ correction
    right = replace(calib.right, T_rover_cam=T)
    if scale:
        right = replace(right, fx_px=right.fx_px * (1.0 + scale), fy_px=right.fy_px * (1.0 + scale))
    return replace(calib, right=right)


@dataclass
class EpipolarCheck:
    """Onboard state of one stereo pair's epipolar check. A pair whose calibration error cannot move its rows past
    ``ROW_FLOOR_PX`` is left alone (:meth:`resolvable`). Until it has a fit, the matched corners of each rectified
    pair it is shown are pooled; once they number ``MIN_MATCHES``, one fit (:func:`fit_row_rotation`: the
    linearisation is exact to well below the matcher's noise for rotations this small) becomes the pair's
    correction for the rest of the run. The rectified frame turns with the cameras, so corners of pairs taken at
    different mast pointings pool."""

    prior_sigma_rad: float | None = None  # the calibration's stated relative-rotation sigma (None: always check)
    fit_scale: bool = False  # also fit the right camera's relative focal length (see the module docstring)
    correction: np.ndarray | None = None  # right camera's frame (see right_correction); None until fitted
    scale: float = 0.0  # fitted relative magnification of the right image (fit_scale; 0 until fitted)
    fit: RowFit | None = None
    _design: list[np.ndarray] = field(default_factory=list)
    _dv: list[np.ndarray] = field(default_factory=list)

    def resolvable(self, rig: StereoRig) -> bool:
        """Whether the calibration's relative rotation (1 sigma) moves ``rig``'s rectified rows by at least
        ``ROW_FLOOR_PX``: else a fit would mostly see resampling offsets (see ``ROW_FLOOR_PX``)."""
        return self.prior_sigma_rad is None or bool(rig.right.fy_px * self.prior_sigma_rad >= ROW_FLOOR_PX)

    def calibration(self, calib: StereoCalibration) -> StereoCalibration:
        """``calib`` as the check has corrected it (unchanged before the fit)."""
        return calib if self.correction is None else refine_calibration(calib, self.correction, self.scale)

    def observe(self, calib: StereoCalibration, rig: StereoRig, left_u8: np.ndarray, right_u8: np.ndarray) -> bool:
        """Pool one pair rectified with ``calib`` (uncorrected; ``rig`` its rectified rig) and fit once enough
        corners are in. True when this pair completed the fit."""
        if self.correction is not None or not self.resolvable(rig):
            return False
        uv_l, uv_r = matched_corners(left_u8, right_u8)
        self._design.append(row_design(uv_r, rig, self.fit_scale))
        self._dv.append(uv_r[:, 1] - uv_l[:, 1])
        n = sum(len(d) for d in self._dv)
        if n < MIN_MATCHES:
            return False
        fit = fit_rows(np.concatenate(self._design), np.concatenate(self._dv))
        self._design.clear()
        self._dv.clear()
        if np.linalg.norm(fit.rotation_rad) > MAX_ROTATION_RAD or abs(fit.scale) > MAX_SCALE:  # mismatches: anew
            return False
        self.fit = fit
        self.correction = right_correction(calib, rig, fit.rotation_rad)
        self.scale = fit.scale
        return True
