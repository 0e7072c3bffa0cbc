"""Trajectories, TUM file IO and odometry metrics (evo-style evaluation core, pure numpy).

A :class:`Trajectory` holds timestamped 6-DOF poses of the rover frame in the world frame (x east, y north, z up),
orientations as ``quat_wxyz`` (rover -> world). Metrics take the trajectory to evaluate (``estimate``) and the one it
is judged against (``reference``, e.g. the simulator's logged rover pose) as arguments; nothing here reads any
simulator state.

Metrics:

* :func:`final_position_error_pct`: final position error as a percentage of the reference path length (the MER
  "10 % of distance" figure of merit).
* :func:`relative_errors`: KITTI-style drift over sub-segments of given path lengths,
  ``E = (P_a^-1 P_b)^-1 (G_a^-1 G_b)``, translational error ``|t(E)| / L``.
* :func:`step_slip`: per-step slip ``1 - made_good / commanded`` (MER definition).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from nav.geometry import R_to_quat_wxyz, quat_wxyz_to_R, se3, se3_inv, so3_log


@dataclass(frozen=True)
class Pose:
    """Pose of the rover frame in the world frame at time ``t_s``."""

    t_s: float
    position_xyz_m: np.ndarray  # (3,) world
    quat_wxyz: np.ndarray  # (4,) rover -> world

    @property
    def R_world_rover(self) -> np.ndarray:
        return quat_wxyz_to_R(self.quat_wxyz)

    def as_matrix(self) -> np.ndarray:
        """4x4 ``T_world_rover``."""
        return se3(self.R_world_rover, self.position_xyz_m)

    @staticmethod
    def from_matrix(T_world_rover: np.ndarray, t_s: float = 0.0) -> Pose:
        return Pose(float(t_s), np.array(T_world_rover[:3, 3], dtype=float), R_to_quat_wxyz(T_world_rover[:3, :3]))

    @staticmethod
    def identity(t_s: float = 0.0) -> Pose:
        return Pose(float(t_s), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))


@dataclass(frozen=True)
class Trajectory:
    """N timestamped poses: ``t_s`` (N,), ``positions_xyz`` (N, 3) m, ``orientations_quat_wxyz`` (N, 4)."""

    t_s: np.ndarray
    positions_xyz: np.ndarray
    orientations_quat_wxyz: np.ndarray

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, dtype=float).reshape(-1)
        p = np.asarray(self.positions_xyz, dtype=float).reshape(-1, 3)
        q = np.asarray(self.orientations_quat_wxyz, dtype=float).reshape(-1, 4)
        if not (len(t) == len(p) == len(q)):
            raise ValueError(f"Trajectory needs equal lengths, got t {len(t)}, positions {len(p)}, quats {len(q)}")
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "positions_xyz", p)
        object.__setattr__(self, "orientations_quat_wxyz", q)

    def __len__(self) -> int:
        return len(self.t_s)

    def __getitem__(self, idx) -> Trajectory:
        idx = np.atleast_1d(np.arange(len(self))[idx])
        return Trajectory(self.t_s[idx], self.positions_xyz[idx], self.orientations_quat_wxyz[idx])

    def pose(self, i: int) -> Pose:
        return Pose(float(self.t_s[i]), self.positions_xyz[i].copy(), self.orientations_quat_wxyz[i].copy())

    def matrices(self) -> np.ndarray:
        """(N, 4, 4) ``T_world_rover`` per pose."""
        T = np.tile(np.eye(4), (len(self), 1, 1))
        T[:, :3, :3] = _quats_to_R(self.orientations_quat_wxyz)
        T[:, :3, 3] = self.positions_xyz
        return T

    def cumulative_distance_m(self) -> np.ndarray:
        """(N,) path length from the first pose to each pose."""
        steps = np.linalg.norm(np.diff(self.positions_xyz, axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(steps)])

    def path_length_m(self) -> float:
        return float(self.cumulative_distance_m()[-1]) if len(self) else 0.0

    @staticmethod
    def from_poses(poses) -> Trajectory:
        """From a sequence of :class:`Pose` (or anything with ``t_s``, ``position_xyz_m``, ``quat_wxyz``)."""
        poses = list(poses)
        return Trajectory(
            np.array([p.t_s for p in poses], dtype=float),
            np.array([p.position_xyz_m for p in poses], dtype=float).reshape(-1, 3),
            np.array([p.quat_wxyz for p in poses], dtype=float).reshape(-1, 4),
        )

    @staticmethod
    def from_matrices(t_s: np.ndarray, T_world_rover: np.ndarray) -> Trajectory:
        T = np.asarray(T_world_rover, dtype=float)
        return Trajectory(t_s, T[:, :3, 3], np.array([R_to_quat_wxyz(R) for R in T[:, :3, :3]]).reshape(-1, 4))

    def transformed(self, T_new_old: np.ndarray) -> Trajectory:
        """The same motion expressed in another world frame: ``T_new_rover = T_new_old @ T_old_rover``."""
        return Trajectory.from_matrices(self.t_s, T_new_old @ self.matrices())


# ----------------------------------------------------------------------------------------------------------------
# TUM format: one pose per line, "t x y z qx qy qz qw" (scalar last), '#' comments
# ----------------------------------------------------------------------------------------------------------------
def write_tum(traj: Trajectory, path: str | Path) -> None:
    """TUM ``t x y z qx qy qz qw`` lines, timestamps strictly increasing: of poses sharing a timestamp (an estimate
    sampled again before its next update, or the VO-corrected pose at a frame time) the last one is written."""
    t = np.asarray(traj.t_s, dtype=float)
    keep = np.ones(len(t), dtype=bool)
    if len(t) > 1:
        keep[:-1] = t[1:] > t[:-1]  # last of each run of equal stamps
        keep &= t >= np.maximum.accumulate(t)  # and never a stamp older than one already seen
    q = traj.orientations_quat_wxyz[keep]
    data = np.column_stack([t[keep], traj.positions_xyz[keep], q[:, 1], q[:, 2], q[:, 3], q[:, 0]])
    np.savetxt(path, data, fmt="%.9f", header="t x y z qx qy qz qw")


def read_tum(path: str | Path) -> Trajectory:
    data = np.loadtxt(path, comments="#", ndmin=2)
    if data.shape[1] != 8:
        raise ValueError(f"{path}: TUM lines need 8 columns 't x y z qx qy qz qw', found {data.shape[1]}")
    return Trajectory(data[:, 0], data[:, 1:4], np.column_stack([data[:, 7], data[:, 4:7]]))


# ----------------------------------------------------------------------------------------------------------------
# Alignment by timestamps
# ----------------------------------------------------------------------------------------------------------------
def interpolate(traj: Trajectory, t_s: np.ndarray) -> Trajectory:
    """Poses at times ``t_s`` (inside the trajectory's time span): linear positions, slerp orientations."""
    t_s = np.asarray(t_s, dtype=float).reshape(-1)
    if len(traj) == 0 or t_s.min() < traj.t_s[0] - 1e-12 or t_s.max() > traj.t_s[-1] + 1e-12:
        raise ValueError("interpolate: requested times fall outside the trajectory's time span")
    i1 = np.clip(np.searchsorted(traj.t_s, t_s, side="right"), 1, max(len(traj) - 1, 1))
    i0 = i1 - 1 if len(traj) > 1 else np.zeros_like(i1)
    dt = traj.t_s[i1] - traj.t_s[i0]
    a = np.where(dt > 0, (t_s - traj.t_s[i0]) / np.where(dt > 0, dt, 1.0), 0.0)
    p = traj.positions_xyz[i0] + a[:, None] * (traj.positions_xyz[i1] - traj.positions_xyz[i0])
    q = np.array(
        [
            slerp_quat_wxyz(traj.orientations_quat_wxyz[j], traj.orientations_quat_wxyz[k], w)
            for j, k, w in zip(i0, i1, a, strict=True)
        ]
    )
    return Trajectory(t_s, p, q.reshape(-1, 4))


def associate(
    estimate: Trajectory,
    reference: Trajectory,
    max_dt_s: float = 0.02,
    method: Literal["nearest", "interpolate"] = "nearest",
) -> tuple[Trajectory, Trajectory]:
    """Pair poses by timestamp: for each estimate pose, the reference pose nearest in time (within ``max_dt_s``) or
    the reference interpolated at that time (estimate poses outside the reference's span are dropped)."""
    if method == "interpolate":
        keep = (estimate.t_s >= reference.t_s[0]) & (estimate.t_s <= reference.t_s[-1])
        est = estimate[keep]
        return est, interpolate(reference, est.t_s)
    j = np.clip(np.searchsorted(reference.t_s, estimate.t_s), 1, len(reference) - 1)
    j = np.where(np.abs(reference.t_s[j - 1] - estimate.t_s) <= np.abs(reference.t_s[j] - estimate.t_s), j - 1, j)
    keep = np.abs(reference.t_s[j] - estimate.t_s) <= max_dt_s
    return estimate[keep], reference[j[keep]]


def align_first_pose(estimate: Trajectory, reference: Trajectory) -> Trajectory:
    """The estimate moved rigidly so that its first pose coincides with the reference's first pose."""
    return estimate.transformed(reference.matrices()[0] @ se3_inv(estimate.matrices()[0]))


# ----------------------------------------------------------------------------------------------------------------
# Metrics
# ----------------------------------------------------------------------------------------------------------------
def final_position_error_pct(estimate: Trajectory, reference: Trajectory, align_first: bool = False) -> float:
    """``100 * |p_est[-1] - p_ref[-1]| / path_length(reference)``; both already paired pose by pose."""
    _check_paired(estimate, reference)
    est = align_first_pose(estimate, reference) if align_first else estimate
    length = reference.path_length_m()
    if length <= 0:
        raise ValueError("final_position_error_pct: the reference does not move (path length 0)")
    return 100.0 * float(np.linalg.norm(est.positions_xyz[-1] - reference.positions_xyz[-1])) / length


@dataclass(frozen=True)
class SegmentErrors:
    """KITTI-style relative errors for one segment length."""

    length_m: float
    n_segments: int
    translation_error_pct: float  # mean |t(E)| / L * 100
    rotation_error_deg_per_m: float  # mean angle(E) / L
    translation_errors: np.ndarray  # per segment, fraction of L


def relative_errors(
    estimate: Trajectory, reference: Trajectory, lengths_m: tuple[float, ...] | list[float], step_frames: int = 1
) -> list[SegmentErrors]:
    """KITTI odometry metric over sub-segments of the reference path of each length ``L`` in ``lengths_m``.

    For each first frame ``a`` (every ``step_frames``) the last frame ``b`` is the first whose reference path length
    from ``a`` reaches L; ``E = (P_a^-1 P_b)^-1 (G_a^-1 G_b)`` with P the estimate and G the reference; errors
    ``|t(E)| / L`` and ``angle(E) / L``. Lengths with no complete segment report NaN.
    """
    _check_paired(estimate, reference)
    P, G = estimate.matrices(), reference.matrices()
    dist = reference.cumulative_distance_m()
    out = []
    for L in lengths_m:
        t_err, r_err = [], []
        for a in range(0, len(reference), step_frames):
            b = int(np.searchsorted(dist, dist[a] + L - 1e-9, side="left"))  # first frame at >= L (to 1 nm)
            if b >= len(reference):
                break
            E = se3_inv(se3_inv(P[a]) @ P[b]) @ (se3_inv(G[a]) @ G[b])
            t_err.append(np.linalg.norm(E[:3, 3]) / L)
            r_err.append(np.degrees(np.linalg.norm(so3_log(E[:3, :3]))) / L)
        t_arr = np.asarray(t_err)
        out.append(
            SegmentErrors(
                float(L),
                len(t_arr),
                100.0 * float(t_arr.mean()) if len(t_arr) else float("nan"),
                float(np.mean(r_err)) if r_err else float("nan"),
                t_arr,
            )
        )
    return out


def made_good_m(reference: Trajectory, indices: np.ndarray | None = None) -> np.ndarray:
    """Distance made good per step: displacement along the rover's body x axis at the step start (3D, signed)."""
    idx = np.arange(len(reference)) if indices is None else np.asarray(indices)
    T = reference.matrices()[idx]
    d = T[1:, :3, 3] - T[:-1, :3, 3]
    return np.einsum("ni,ni->n", d, T[:-1, :3, 0])


def step_slip(reference: Trajectory, commanded_distance_m: np.ndarray, indices: np.ndarray | None = None) -> np.ndarray:
    """Per-step slip ``1 - made_good / commanded`` (MER). Steps join consecutive ``indices`` (default all poses);
    ``commanded_distance_m`` (one per step, signed, e.g. wheel-odometry distance) must be non-zero; 1.25 means
    the rover slid back a quarter of the commanded distance (Spirit, Sol 206)."""
    commanded = np.asarray(commanded_distance_m, dtype=float)
    good = made_good_m(reference, indices)
    if len(good) != len(commanded):
        raise ValueError(f"step_slip: {len(good)} steps but {len(commanded)} commanded distances")
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.abs(commanded) > 1e-12, 1.0 - good / commanded, np.nan)


# ----------------------------------------------------------------------------------------------------------------
def _check_paired(estimate: Trajectory, reference: Trajectory) -> None:
    if len(estimate) != len(reference) or len(reference) == 0:
        raise ValueError(
            f"metrics need paired trajectories of equal length (got {len(estimate)} and {len(reference)}); "
            "pair them first with nav.trajectory.associate()"
        )


def _quats_to_R(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )


def slerp_quat_wxyz(q0: np.ndarray, q1: np.ndarray, a: float) -> np.ndarray:
    """Spherical linear interpolation from ``q0`` (a=0) to ``q1`` (a=1), shortest arc."""
    d = float(q0 @ q1)
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + a * (q1 - q0)
        return q / np.linalg.norm(q)
    th = np.arccos(d)
    return (np.sin((1 - a) * th) * q0 + np.sin(a * th) * q1) / np.sin(th)
