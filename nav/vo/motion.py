"""Geometry side of the MER visual odometry: triangulation, covariance, robust and ML motion, sanity checks.

Cheng, Maimone, Matthies (2005), section 2: equations (1)-(11) (steps 3-4), "Robust Motion Estimation" (steps
6-7, equations (12)-(17)) and the optional sanity constraints (step 8).

Motion convention inside this module follows the paper: ``(R, T)`` maps feature positions in the previous
rover frame to the current one, ``P_c = R P_p + T``. The rover's motion (pose of the current rover frame in
the previous one) is its inverse, see :func:`motion_from_RT`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nav.camera import PinholeCamera, StereoRig
from nav.geometry import R_to_rpy, se3, se3_inv, skew, so3_exp, so3_log
from nav.vo.params import SanityConstraints, VoParams


# ------------------------------------------------------------------------------------------------------------
# Step 3: triangulation with a gap test
# ------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Triangulation:
    points: np.ndarray  # (N, 3) midpoints P = (P1 + P2) / 2
    gap_m: np.ndarray  # (N,) |P1 - P2|, the shortest distance between the rays
    m1: np.ndarray  # (N,) distance along ray 1 (r1 unit) to P1
    m2: np.ndarray  # (N,) distance along ray 2 to P2
    ok: np.ndarray  # (N,) rays not parallel and converging in front of both cameras


def triangulate_rays(C1: np.ndarray, r1: np.ndarray, C2: np.ndarray, r2: np.ndarray) -> Triangulation:
    """Paper eqs. (1)-(7): closest points of rays ``C1 + m1 r1``, ``C2 + m2 r2`` (unit r) and their midpoint.

    ``m1 = (B.r1 - (B.r2)(r1.r2)) / (1 - (r1.r2)^2)``, ``m2 = (r1.r2) m1 - B.r2``, ``B = C2 - C1``.
    Vectorised: C1, C2 broadcast against (N, 3) rays.
    """
    r1 = np.atleast_2d(r1)
    r2 = np.atleast_2d(r2)
    B = np.asarray(C2, dtype=float) - np.asarray(C1, dtype=float)
    c = np.sum(r1 * r2, axis=-1)
    br1 = np.sum(B * r1, axis=-1)
    br2 = np.sum(B * r2, axis=-1)
    den = 1.0 - c * c
    parallel = den < 1e-12
    with np.errstate(divide="ignore", invalid="ignore"):
        m1 = (br1 - br2 * c) / np.where(parallel, 1.0, den)
    m2 = c * m1 - br2
    P1 = C1 + r1 * m1[:, None]
    P2 = C2 + r2 * m2[:, None]
    ok = ~parallel & (m1 > 0) & (m2 > 0)
    return Triangulation((P1 + P2) / 2.0, np.linalg.norm(P1 - P2, axis=-1), m1, m2, ok)


def pixel_rays_rover(cam: PinholeCamera, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre (3,) and unit viewing rays (N, 3) through pixels ``uv``, in the rover frame."""
    return cam.T_rover_cam[:3, 3].copy(), cam.ray(uv) @ cam.T_rover_cam[:3, :3].T


def triangulate_stereo(rig: StereoRig, uv_left: np.ndarray, uv_right: np.ndarray) -> Triangulation:
    """Triangulate matched pixels of a stereo rig; points in the rover frame."""
    C1, r1 = pixel_rays_rover(rig.left, uv_left)
    C2, r2 = pixel_rays_rover(rig.right, uv_right)
    return triangulate_rays(C1, r1, C2, r2)


def gap_test(tri: Triangulation, rig: StereoRig, max_gap_px: float, max_range_m: float) -> np.ndarray:
    """Step 3's rejection: ray gap, as an image-plane distance at the feature's range, <= ``max_gap_px``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        gap_px = tri.gap_m / np.maximum(tri.m1, 1e-9) * rig.left.fx_px
    return tri.ok & (gap_px <= max_gap_px) & (tri.m1 <= max_range_m) & np.isfinite(tri.points).all(axis=1)


# ------------------------------------------------------------------------------------------------------------
# Step 4: feature covariance
# ------------------------------------------------------------------------------------------------------------
def feature_covariance(
    rig: StereoRig,
    uv_left: np.ndarray,
    uv_right: np.ndarray,
    cov_left_px2: np.ndarray,
    cov_right_px2: np.ndarray,
    step_px: float = 0.05,
) -> np.ndarray:
    """Paper eq. (11): ``Sigma_P = J diag(Sigma_l, Sigma_r) J^T``, J = dP/d(u_l, v_l, u_r, v_r) (N, 3, 3).

    J by central differences of the midpoint triangulation (the paper's eqs. (8)-(10) differentiate the same
    map).
    """
    uv_left = np.atleast_2d(uv_left).astype(float)
    uv_right = np.atleast_2d(uv_right).astype(float)
    n = len(uv_left)
    J = np.empty((n, 3, 4))
    for k in range(4):
        d = np.zeros(4)
        d[k] = step_px
        plus = triangulate_stereo(rig, uv_left + d[:2], uv_right + d[2:]).points
        minus = triangulate_stereo(rig, uv_left - d[:2], uv_right - d[2:]).points
        J[:, :, k] = (plus - minus) / (2.0 * step_px)
    S = np.zeros((n, 4, 4))
    S[:, :2, :2] = cov_left_px2
    S[:, 2:, 2:] = cov_right_px2
    return J @ S @ J.transpose(0, 2, 1)


# ------------------------------------------------------------------------------------------------------------
# Step 6: RANSAC with the weighted closed-form least-squares motion
# ------------------------------------------------------------------------------------------------------------
def feature_weights(cov_prev: np.ndarray, cov_cur: np.ndarray) -> np.ndarray:
    """Scalar least-squares weight per feature from its error-ellipsoid volumes.

    Paper eq. (14) uses ``1 / (det Sigma_p + det Sigma_c)``. Determinants grow like range^8 for stereo, so
    that weight lets the few nearest features dominate; we use its cube root, ``(det Sigma_p + det
    Sigma_c)^(-1/3)``, which keeps the paper's ordering by ellipsoid volume but has the units of an inverse
    variance (1/m^2).
    """
    d = np.linalg.det(cov_prev) + np.linalg.det(cov_cur)
    return 1.0 / np.cbrt(np.maximum(d, 1e-30))


def rigid_lsq(P_prev: np.ndarray, P_cur: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form weighted least squares ``min sum w |P_c - R P_p - T|^2`` (Arun/Umeyama SVD), batched.

    Shapes (..., k, 3), (..., k, 3), (..., k) -> R (..., 3, 3), T (..., 3).
    """
    w = w / np.sum(w, axis=-1, keepdims=True)
    cp = np.sum(w[..., None] * P_prev, axis=-2)
    cc = np.sum(w[..., None] * P_cur, axis=-2)
    A = P_prev - cp[..., None, :]
    Bc = P_cur - cc[..., None, :]
    H = np.einsum("...k,...ki,...kj->...ij", w, A, Bc)
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, -1, -2)
    d = np.sign(np.linalg.det(V @ np.swapaxes(U, -1, -2)))
    d = np.where(d == 0, 1.0, d)
    D = np.zeros(H.shape)
    D[..., 0, 0] = 1.0
    D[..., 1, 1] = 1.0
    D[..., 2, 2] = d
    R = V @ D @ np.swapaxes(U, -1, -2)
    T = cc - np.einsum("...ij,...j->...i", R, cp)
    return R, T


def reprojection_error_px(
    R: np.ndarray,
    T: np.ndarray,
    P_prev: np.ndarray,
    uv_left: np.ndarray,
    uv_right: np.ndarray,
    rig: StereoRig,
) -> np.ndarray:
    """Max over the left and right images of the pixel distance between ``R P_prev + T`` and its observation.

    R (..., 3, 3), T (..., 3), P_prev (N, 3) -> errors (..., N); NaN behind a camera.
    """
    Pc = np.einsum("...ij,nj->...ni", R, P_prev) + T[..., None, :]
    err = None
    for cam, uv in ((rig.left, uv_left), (rig.right, uv_right)):
        T_cam_rover = se3_inv(cam.T_rover_cam)
        X = Pc @ T_cam_rover[:3, :3].T + T_cam_rover[:3, 3]
        z = X[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = cam.fx_px * X[..., 0] / z + cam.cx_px
            v = cam.fy_px * X[..., 1] / z + cam.cy_px
        e = np.hypot(u - uv[:, 0], v - uv[:, 1])
        e = np.where(z > 0, e, np.nan)
        err = e if err is None else np.fmax(err, e)
    return err


@dataclass(frozen=True)
class RansacResult:
    R: np.ndarray  # (3, 3) P_c = R P_p + T
    T: np.ndarray  # (3,)
    inliers: np.ndarray  # (N,) bool
    n_inliers: int
    error_px: np.ndarray  # (N,) reprojection error under (R, T)


def ransac_motion(
    P_prev: np.ndarray,
    P_cur: np.ndarray,
    Sigma_prev: np.ndarray,
    Sigma_cur: np.ndarray,
    uv_cur_left: np.ndarray,
    uv_cur_right: np.ndarray,
    rig: StereoRig,
    params: VoParams,
    rng: np.random.Generator | None = None,
) -> RansacResult:
    """Step 6: RANSAC over random subsets of ``ransac_subset_size`` features.

    Each hypothesis is the weighted closed-form least-squares motion of its subset (:func:`rigid_lsq`,
    :func:`feature_weights`); its score is the number of features whose previous 3D position, moved by the
    hypothesis and projected into the current left and right images, lands within ``inlier_threshold_px`` of
    the tracked position (ties broken by smaller total error). The best hypothesis is refitted once on its
    inliers. All hypotheses are evaluated at once (batched SVD).
    """
    n = len(P_prev)
    rng = np.random.default_rng(params.ransac_seed) if rng is None else rng
    w = feature_weights(Sigma_prev, Sigma_cur)
    k = min(params.ransac_subset_size, n)
    if n < 3:
        return RansacResult(np.eye(3), np.zeros(3), np.zeros(n, bool), 0, np.full(n, np.inf))
    # random subsets without repetition inside a subset: argsort of uniform keys
    idx = np.argsort(rng.random((params.ransac_iterations, n)), axis=1)[:, :k]
    R, T = rigid_lsq(P_prev[idx], P_cur[idx], w[idx])
    err = reprojection_error_px(R, T, P_prev, uv_cur_left, uv_cur_right, rig)
    err = np.where(np.isfinite(err), err, np.inf)
    inl = err < params.inlier_threshold_px
    count = inl.sum(axis=1)
    cost = np.where(inl, err, params.inlier_threshold_px).sum(axis=1)
    best = int(np.lexsort((cost, -count))[0])
    R_b, T_b, inl_b, err_b = R[best], T[best], inl[best], err[best]
    if inl_b.sum() >= 3:  # local refit on the whole consensus set
        R2, T2 = rigid_lsq(P_prev[inl_b], P_cur[inl_b], w[inl_b])
        e2 = reprojection_error_px(R2, T2, P_prev, uv_cur_left, uv_cur_right, rig)
        e2 = np.where(np.isfinite(e2), e2, np.inf)
        i2 = e2 < params.inlier_threshold_px
        if i2.sum() >= inl_b.sum():
            R_b, T_b, inl_b, err_b = R2, T2, i2, e2
    return RansacResult(R_b, T_b, inl_b, int(inl_b.sum()), err_b)


# ------------------------------------------------------------------------------------------------------------
# Step 7: maximum-likelihood refinement
# ------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MlResult:
    R: np.ndarray  # (3, 3) P_c = R P_p + T
    T: np.ndarray  # (3,)
    covariance: np.ndarray  # (6, 6) of (rotation increment [rad], T [m]): R = exp([d]x) R_hat, T = T_hat + dT
    converged: bool
    iterations: int
    inliers: np.ndarray  # (N,) bool: features kept (all, unless ml_outlier_chi2 dropped some)
    chi2: np.ndarray  # (N,) e^T W e at the solution
    variance_factor: float  # s2 >= 1 applied to the covariance


def ml_refine(
    P_prev: np.ndarray,
    P_cur: np.ndarray,
    Sigma_prev: np.ndarray,
    Sigma_cur: np.ndarray,
    R0: np.ndarray,
    T0: np.ndarray,
    params: VoParams,
) -> MlResult:
    """Step 7, paper eqs. (15)-(17): minimise ``sum e^T W e``, ``e = P_c - R P_p - T``,
    ``W = (S_c + R S_p R^T)^-1``.

    Gauss-Newton over the three rotation angles (a rotation-vector increment applied on the left of the
    current R, i.e. small rotations about the rover axes) and T, with W re-evaluated at each iterate. The 6x6
    covariance is the inverse of the Gauss-Newton normal matrix at the solution, scaled by the a-posteriori
    variance factor ``s2 = max(1, median(e^T W e) / 2.366)`` (2.366 = median of chi^2 with 3 dof) when the
    feature covariances turn out optimistic (view-change distortion of the correlation windows is not in the
    pixel noise model). With ``ml_outlier_chi2`` set, features whose ``e^T W e / s2`` exceeds it are dropped
    once and the estimate is recomputed (an addition to the paper).
    """
    keep = np.ones(len(P_prev), bool)
    R, T = np.asarray(R0, dtype=float).copy(), np.asarray(T0, dtype=float).copy()
    rounds = 2 if params.ml_outlier_chi2 is not None else 1
    total_it = 0
    converged = False
    A = np.eye(6)
    s2 = 1.0
    for _ in range(rounds):
        R, T, A, converged, it = _gauss_newton(
            P_prev[keep], P_cur[keep], Sigma_prev[keep], Sigma_cur[keep], R, T, params
        )
        total_it += it
        chi2 = _chi2(P_prev, P_cur, Sigma_prev, Sigma_cur, R, T)
        s2 = max(1.0, float(np.median(chi2[keep])) / _CHI2_3_MEDIAN)
        if params.ml_outlier_chi2 is None:
            break
        new_keep = keep & (chi2 / s2 <= params.ml_outlier_chi2)
        if new_keep.sum() == keep.sum() or new_keep.sum() < 3:
            break
        keep = new_keep
    try:
        cov = np.linalg.inv(A) * s2
    except np.linalg.LinAlgError:
        cov = np.full((6, 6), np.inf)
        converged = False
    return MlResult(R, T, cov, converged, total_it, keep, _chi2(P_prev, P_cur, Sigma_prev, Sigma_cur, R, T), s2)


_CHI2_3_MEDIAN = 2.366


def _chi2(Pp, Pc, Sp, Sc, R, T) -> np.ndarray:
    e = Pc - Pp @ R.T - T
    W = np.linalg.inv(Sc + R @ Sp @ R.T)
    return np.einsum("ni,nij,nj->n", e, W, e)


def _residual_jacobian(q: np.ndarray) -> np.ndarray:
    """de/d(delta, dT) (N, 3, 6) of ``e = P_c - exp([delta]x) q - T - dT`` at 0: ``[[q]x, -I]``."""
    J = np.zeros((len(q), 3, 6))
    J[:, 0, 1], J[:, 0, 2] = -q[:, 2], q[:, 1]
    J[:, 1, 0], J[:, 1, 2] = q[:, 2], -q[:, 0]
    J[:, 2, 0], J[:, 2, 1] = -q[:, 1], q[:, 0]
    J[:, :, 3:] = -np.eye(3)
    return J


def _gauss_newton(Pp, Pc, Sp, Sc, R, T, params: VoParams):
    A = np.eye(6)
    for it in range(1, params.ml_max_iterations + 1):
        q = Pp @ R.T
        e = Pc - q - T
        W = np.linalg.inv(Sc + R @ Sp @ R.T)
        J = _residual_jacobian(q)
        JtW = J.transpose(0, 2, 1) @ W
        A = np.einsum("nij,njk->ik", JtW, J)
        b = np.einsum("nij,nj->i", JtW, e)
        try:
            dx = -np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            return R, T, A, False, it
        R = so3_exp(dx[:3]) @ R
        T = T + dx[3:]
        if np.linalg.norm(dx[:3]) < params.ml_tol_rad and np.linalg.norm(dx[3:]) < params.ml_tol_m:
            # normal matrix at the solution
            q = Pp @ R.T
            W = np.linalg.inv(Sc + R @ Sp @ R.T)
            J = _residual_jacobian(q)
            A = np.einsum("nji,njk,nkl->il", J, W, J)
            return R, T, A, True, it
    return R, T, A, False, params.ml_max_iterations


# ------------------------------------------------------------------------------------------------------------
# Motion conventions
# ------------------------------------------------------------------------------------------------------------
def motion_from_RT(R: np.ndarray, T: np.ndarray, cov_RT: np.ndarray | None = None):
    """Rover motion ``M`` (4x4, pose of the current rover frame in the previous one) from ``P_c = R P_p + T``.

    Returns ``(M, cov_M)``; ``cov_M`` (6x6) is over ``(dt, dtheta)`` with ``M = (exp([dtheta]x) R_M, t_M +
    dt)``, i.e. translation (m) and rotation (rad) errors both expressed in the previous rover frame.
    """
    M = se3_inv(se3(R, T))
    if cov_RT is None:
        return M, None
    Rt = R.T
    A = np.zeros((6, 6))
    A[:3, :3] = -Rt @ skew(T)
    A[:3, 3:] = -Rt
    A[3:, :3] = -Rt
    return M, A @ cov_RT @ A.T


def motion_magnitude(M: np.ndarray) -> tuple[float, float]:
    """(translation m, rotation angle rad) of a 4x4 motion."""
    return float(np.linalg.norm(M[:3, 3])), float(np.linalg.norm(so3_log(M[:3, :3])))


# ------------------------------------------------------------------------------------------------------------
# Step 8: sanity constraints
# ------------------------------------------------------------------------------------------------------------
def downslope_direction(R_world_rover: np.ndarray, min_tilt_rad: float = np.radians(1.0)) -> np.ndarray | None:
    """Unit world-frame direction of steepest descent in the rover's ground plane; None on level ground."""
    n = R_world_rover[:, 2]
    down = np.array([0.0, 0.0, -1.0])
    d = down - (down @ n) * n
    norm = float(np.linalg.norm(d))
    return None if norm < np.sin(min_tilt_rad) else d / norm


def sanity_check(
    motion_rover: np.ndarray,
    predicted_motion_rover: np.ndarray,
    constraints: SanityConstraints,
    R_world_rover: np.ndarray | None = None,
) -> tuple[bool, str]:
    """Step 8: check the VO update (VO motion minus the predicted motion) against the optional limits.

    Translation update ``t_vo - t_pred`` is expressed in the site frame with the previous attitude
    ``R_world_rover`` (IMU), else in the previous rover frame. Roll/pitch/yaw updates are differences of the
    attitudes the two motions give (about the rover axes without attitude). Returns ``(ok, reason)``.
    """
    c = constraints
    dt = motion_rover[:3, 3] - predicted_motion_rover[:3, 3]
    R0 = np.eye(3) if R_world_rover is None else np.asarray(R_world_rover, dtype=float)
    dt_site = R0 @ dt
    rpy_vo = R_to_rpy(R0 @ motion_rover[:3, :3])
    rpy_pred = R_to_rpy(R0 @ predicted_motion_rover[:3, :3])
    d_rpy = np.degrees(np.abs((rpy_vo - rpy_pred + np.pi) % (2 * np.pi) - np.pi))
    checks = [
        (c.max_update_m, float(np.linalg.norm(dt)), "update magnitude {v:.3f} m > {lim} m"),
        (c.max_update_x_m, abs(float(dt_site[0])), "update X {v:.3f} m > {lim} m"),
        (c.max_update_y_m, abs(float(dt_site[1])), "update Y {v:.3f} m > {lim} m"),
        (c.max_roll_update_deg, float(d_rpy[0]), "roll update {v:.2f} deg > {lim} deg"),
        (c.max_pitch_update_deg, float(d_rpy[1]), "pitch update {v:.2f} deg > {lim} deg"),
        (c.max_yaw_update_deg, float(d_rpy[2]), "yaw update {v:.2f} deg > {lim} deg"),
    ]
    for lim, value, msg in checks:
        if lim is not None and value > lim:
            return False, msg.format(v=value, lim=lim)
    if c.max_downslope_angle_deg is not None and R_world_rover is not None:
        down = downslope_direction(R0)
        if down is not None and np.linalg.norm(dt_site) >= c.min_update_for_direction_m:
            ang = np.degrees(np.arccos(np.clip(dt_site @ down / np.linalg.norm(dt_site), -1.0, 1.0)))
            if ang > c.max_downslope_angle_deg:
                return False, f"update {ang:.1f} deg from downslope > {c.max_downslope_angle_deg} deg"
    return True, ""
