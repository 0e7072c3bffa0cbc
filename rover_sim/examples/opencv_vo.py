"""A compact "bring your own" stereo visual odometer built from stock OpenCV parts.

:class:`OpenCvStereoVO` implements :class:`nav.protocols.VisualOdometer` and nothing more; it is an example of a
plugin, not a replacement for the built-in :class:`nav.vo.VisualOdometry`. One :meth:`~OpenCvStereoVO.step`:

1. Shi-Tomasi corners in the new left image (with an absolute floor on the corner response, so featureless soil
   gives no features rather than noise corners), matched along the same row of the right image (the pair is rectified)
   by normalised cross-correlation with a parabolic sub-pixel peak, triangulated into the left camera frame and
   placed in the rover frame with ``rig.left.T_rover_cam``. These are kept for the next step.
2. The previous pair's features are tracked into the new left image with pyramidal KLT, the initial flow being the
   previous 3D points projected through ``predicted_motion_rover`` (dead reckoning), and kept only if tracking back
   lands within half a pixel of where they started. The seed matters: without a prediction, KLT loses most
   features on a 30 cm step of a navcam pitched 40 deg down and the step is refused.
3. ``cv2.solvePnPRansac`` on (previous rover-frame 3D point, new left pixel) gives the pose of the previous rover
   frame in the new camera, refined on the inliers with ``cv2.solvePnPRefineLM``; ``motion_rover`` (pose of the new
   rover frame in the previous one) follows from the camera extrinsics.
4. Covariance: ``sigma^2 (J^T J)^-1`` of the inlier reprojection residuals, ``J`` by finite differences over the
   contract's (dx, dy, dz, dtheta) in the previous rover frame, ``sigma`` from the residuals. It ignores the
   triangulation error of the 3D points beyond what the residuals show, so it is optimistic: on the synthetic
   scenes of the tests the actual error is several times the stated sigma.

What it is not: there are none of the MER flight checks (no per-feature stereo covariances or maximum-likelihood
motion, no sanity constraints against the predicted motion, no re-initialisation on large predicted steps, no
guard against two rigid motions in view such as the rover's own shadow, no failure counting). ``R_world_rover`` is
ignored. A step is refused only when too few features are found, tracked or agree on one motion.
"""

from __future__ import annotations

import cv2
import numpy as np

from nav.camera import StereoRig
from nav.vo import VoResult

__all__ = ["OpenCvStereoVO"]


def _inv(T: np.ndarray) -> np.ndarray:
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = R.T, -R.T @ t
    return out


def _project(T_cam_x: np.ndarray, P_x: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) of points ``P_x`` (N, 3) seen by a camera at ``T_cam_x``; NaN behind the camera."""
    p = P_x @ T_cam_x[:3, :3].T + T_cam_x[:3, 3]
    z = np.where(p[:, 2] > 1e-6, p[:, 2], np.nan)
    return np.stack([K[0, 0] * p[:, 0] / z + K[0, 2], K[1, 1] * p[:, 1] / z + K[1, 2]], axis=1)


class OpenCvStereoVO:
    """Frame-to-frame stereo VO: corners + row NCC stereo, KLT tracking seeded by the prediction, PnP RANSAC."""

    def __init__(
        self,
        max_corners: int = 400,
        min_corner_quality: float = 1e-4,  # absolute floor on the Shi-Tomasi response (grey levels^2, per pixel)
        patch_px: int = 11,
        min_ncc: float = 0.85,
        max_disparity_px: int = 128,
        klt_window_px: int = 21,
        ransac_threshold_px: float = 1.0,
        min_inliers: int = 20,
    ) -> None:
        self.max_corners, self.min_corner_quality = max_corners, min_corner_quality
        self.half, self.min_ncc, self.max_disparity_px = patch_px // 2, min_ncc, max_disparity_px
        self.klt_window_px, self.ransac_threshold_px, self.min_inliers = klt_window_px, ransac_threshold_px, min_inliers
        self._prev: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # left image, uv (N, 2), P_rover (N, 3)

    def reset(self) -> None:
        self._prev = None

    def step(
        self,
        left_u8: np.ndarray,
        right_u8: np.ndarray,
        rig: StereoRig,
        predicted_motion_rover: np.ndarray | None = None,
        R_world_rover: np.ndarray | None = None,
    ) -> VoResult:
        prev, self._prev = self._prev, (left_u8, *self._features(left_u8, right_u8, rig))
        if prev is None:
            return VoResult("first_frame", n_features=len(self._prev[1]))
        img0, uv0, P0 = prev
        res = VoResult("ok", n_features=len(uv0))
        if len(uv0) < self.min_inliers:
            return self._refuse(res, "too_few_features", f"{len(uv0)} stereo features in the previous pair")
        pred = np.eye(4) if predicted_motion_rover is None else np.asarray(predicted_motion_rover, dtype=float)
        T_cam_rover = _inv(rig.left.T_rover_cam)
        guess = _project(T_cam_rover @ _inv(pred), P0, rig.left.K)  # where the prediction puts them now
        guess = np.where(np.isfinite(guess), guess, uv0)
        uv1, tracked = self._track(img0, left_u8, uv0, guess, self.klt_window_px)
        res.n_tracked = int(tracked.sum())
        if res.n_tracked < self.min_inliers:
            return self._refuse(res, "too_few_features", f"{res.n_tracked} of {len(uv0)} features tracked")
        obj, img, K = P0[tracked], uv1[tracked], rig.left.K
        ok, rvec, tvec, inl = cv2.solvePnPRansac(
            obj, img, K, None, iterationsCount=200, reprojectionError=self.ransac_threshold_px, confidence=0.999
        )
        if not ok or inl is None or len(inl) < self.min_inliers:
            return self._refuse(res, "no_convergence", f"PnP RANSAC: {0 if inl is None else len(inl)} inliers")
        inl = inl.ravel()
        rvec, tvec = cv2.solvePnPRefineLM(obj[inl], img[inl], K, None, rvec, tvec)
        T_cam1_rover0 = np.eye(4)
        T_cam1_rover0[:3, :3], T_cam1_rover0[:3, 3] = cv2.Rodrigues(rvec)[0], tvec.ravel()
        motion = _inv(rig.left.T_rover_cam @ T_cam1_rover0)  # T_rover0_rover1 = (T_rover1_cam1 T_cam1_rover0)^-1
        err = np.linalg.norm(_project(T_cam_rover @ _inv(motion), obj, K) - img, axis=1)
        final = np.flatnonzero(err < self.ransac_threshold_px)
        if len(final) < self.min_inliers:
            return self._refuse(res, "no_convergence", f"{len(final)} inliers after refinement")
        res.motion_rover = motion
        res.covariance = self._covariance(motion, obj[final], img[final], T_cam_rover, K)
        res.n_inliers = len(final)
        res.inliers = np.zeros(len(uv0), bool)
        res.inliers[np.flatnonzero(tracked)[final]] = True
        return res

    # --- the parts ----------------------------------------------------------------------------------------
    def _features(self, left: np.ndarray, right: np.ndarray, rig: StereoRig) -> tuple[np.ndarray, np.ndarray]:
        """Corners of the left image with a row match in the right one: pixels (N, 2), rover-frame points (N, 3)."""
        h = self.half
        corners = cv2.goodFeaturesToTrack(left, self.max_corners, 0.01, minDistance=7, blockSize=7)
        if corners is None:
            return np.zeros((0, 2)), np.zeros((0, 3))
        uv = corners.reshape(-1, 2).round().astype(int)
        H, W = left.shape
        eig = cv2.cornerMinEigenVal(left, 7)  # OpenCV normalises this by the block area and 255^2
        keep = (uv[:, 0] >= h) & (uv[:, 0] < W - h) & (uv[:, 1] >= h) & (uv[:, 1] < H - h)
        keep &= eig[uv[:, 1], uv[:, 0]] >= self.min_corner_quality
        uv, disp = uv[keep], np.full(int(keep.sum()), np.nan)
        for i, (u, v) in enumerate(uv):
            lo = max(h, u - self.max_disparity_px)  # candidate right-image columns lo .. u - 1 (disparity >= 1)
            if u - 1 - lo < 2:
                continue
            tpl = left[v - h : v + h + 1, u - h : u + h + 1]
            score = cv2.matchTemplate(right[v - h : v + h + 1, lo - h : u + h], tpl, cv2.TM_CCOEFF_NORMED)[0]
            k = int(np.argmax(score))
            if score[k] < self.min_ncc or k in (0, len(score) - 1):
                continue
            a, b, c = score[k - 1], score[k], score[k + 1]
            disp[i] = u - (lo + k + 0.5 * (a - c) / (a - 2 * b + c))
        ok = np.isfinite(disp) & (disp > 0.5)
        uv, disp = uv[ok].astype(float), disp[ok]
        cam, B = rig.left, rig.baseline_m
        Z = cam.fx_px * B / disp
        P_cam = np.stack([(uv[:, 0] - cam.cx_px) * Z / cam.fx_px, (uv[:, 1] - cam.cy_px) * Z / cam.fy_px, Z], axis=1)
        return uv, P_cam @ cam.T_rover_cam[:3, :3].T + cam.T_rover_cam[:3, 3]

    @staticmethod
    def _track(img0: np.ndarray, img1: np.ndarray, uv0: np.ndarray, guess: np.ndarray, win: int):
        """KLT from ``img0`` to ``img1`` starting at ``guess``, with a forward-backward check (< 0.5 px)."""
        lk = {"winSize": (win, win), "maxLevel": 3, "flags": cv2.OPTFLOW_USE_INITIAL_FLOW}
        p0, g = uv0.astype(np.float32).reshape(-1, 1, 2), guess.astype(np.float32).reshape(-1, 1, 2)
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(img0, img1, p0, g.copy(), **lk)
        back, st2, _ = cv2.calcOpticalFlowPyrLK(img1, img0, p1, p0.copy(), **lk)
        good = (st1.ravel() == 1) & (st2.ravel() == 1) & (np.linalg.norm((back - p0).reshape(-1, 2), axis=1) < 0.5)
        return p1.reshape(-1, 2).astype(float), good

    @staticmethod
    def _covariance(motion: np.ndarray, P0: np.ndarray, uv1: np.ndarray, T_cam_rover: np.ndarray, K: np.ndarray):
        """6x6 over (dx, dy, dz, dtheta), ``motion = (exp([dtheta]x) R, t + dt)``, from the reprojection residuals."""

        def residuals(xi: np.ndarray) -> np.ndarray:
            M = motion.copy()
            M[:3, :3] = cv2.Rodrigues(xi[3:])[0] @ motion[:3, :3]
            M[:3, 3] += xi[:3]
            return (_project(T_cam_rover @ _inv(M), P0, K) - uv1).ravel()

        r0, eps = residuals(np.zeros(6)), 1e-6
        J = np.stack([(residuals(eps * e) - r0) / eps for e in np.eye(6)], axis=1)
        sigma2 = max(float(r0 @ r0) / max(len(r0) - 6, 1), 0.05**2)  # floor: never claim better than 0.05 px
        cov = sigma2 * np.linalg.inv(J.T @ J)
        return 0.5 * (cov + cov.T)

    @staticmethod
    def _refuse(res: VoResult, status: str, reason: str) -> VoResult:
        res.status, res.reason = status, reason
        return res
