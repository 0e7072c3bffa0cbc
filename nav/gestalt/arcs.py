"""Step 3 of GESTALT (Maimone et al. 2005, section 4.2): "23 forward arcs, 23 backward arcs, and two point turns"
(:func:`arcs`), and their traversability votes, "adding up the goodness scores along each arc, with nearby
cells given higher weight" over the rover's swept footprint (:func:`vote_arcs`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nav.gestalt.map import GoodnessWindow
from nav.gestalt.params import GestaltParams

# ----------------------------------------------------------------------------------------------------------------
# Arcs
# ----------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Arc:
    """A candidate steering command: a circular arc driven forward or backward, or a point turn.

    ``poses_xy_yaw`` samples the rover's path in the rover frame at the start (x forward, y left, yaw left-positive)
    up to ``look_ahead_m``; for a point turn the heading sweep at the origin.
    """

    # 1 / radius of the steering circle, centred at (0, 1 / k) in the rover frame: positive turns left driving
    # forward; driving backward on the same circle the rover backs to the left (point turn: 0)
    curvature_per_m: float
    direction: int  # +1 forward, -1 backward, 0 point turn
    turn_rad: float  # point turns: signed heading change; arcs: heading change over the look-ahead
    poses_xy_yaw: np.ndarray = field(repr=False)

    @property
    def name(self) -> str:
        if self.direction == 0:
            return f"turn_{'left' if self.turn_rad > 0 else 'right'}"
        return f"{'fwd' if self.direction > 0 else 'back'}_k{self.curvature_per_m:+.3f}"


def arc_pose(curvature_per_m: float, signed_distance_m: np.ndarray) -> np.ndarray:
    """Rover-frame poses (x, y, yaw) after driving ``signed_distance_m`` (negative = backward) on a circle."""
    s = np.asarray(signed_distance_m, dtype=float)
    k = curvature_per_m
    yaw = k * s
    if abs(k) < 1e-9:
        return np.stack([s, np.zeros_like(s), np.zeros_like(s)], axis=-1)
    return np.stack([np.sin(yaw) / k, (1.0 - np.cos(yaw)) / k, yaw], axis=-1)


def arcs(params: GestaltParams = GestaltParams()) -> list[Arc]:
    """Paper: 23 forward arcs, 23 backward arcs and 2 point turns, curvatures symmetric about straight."""
    p = params
    ds = p.cell_size_m / 2
    s = np.linspace(0.0, p.look_ahead_m, int(np.ceil(p.look_ahead_m / ds)) + 1)
    out: list[Arc] = []
    for direction, count in ((+1, p.n_forward_arcs), (-1, p.n_backward_arcs)):
        curvatures = np.linspace(-p.max_curvature_per_m, p.max_curvature_per_m, count) if count > 1 else [0.0] * count
        for k in curvatures:
            k = 0.0 if abs(k) < 1e-12 else float(k)
            out.append(Arc(k, direction, k * direction * p.look_ahead_m, arc_pose(k, direction * s)))
    for sign in (+1, -1):
        turn = sign * np.radians(p.point_turn_deg)
        yaw = np.linspace(0.0, turn, 10)
        out.append(Arc(0.0, 0, float(turn), np.stack([np.zeros(10), np.zeros(10), yaw], axis=-1)))
    return out


def goal_arc(
    pose_xy_yaw: np.ndarray, goal_xy: np.ndarray, params: GestaltParams = GestaltParams()
) -> tuple[Arc, float] | None:
    """The forward arc from the pose through the goal and its length, if the goal is within
    ``capture_distance_m``, ahead, and reachable within ``max_curvature_per_m``; else None."""
    p = params
    x, y, yaw = (float(v) for v in pose_xy_yaw)
    dx, dy = float(goal_xy[0]) - x, float(goal_xy[1]) - y
    gx = np.cos(yaw) * dx + np.sin(yaw) * dy
    gy = -np.sin(yaw) * dx + np.cos(yaw) * dy
    d2 = gx * gx + gy * gy
    if d2 > p.capture_distance_m**2 or gx <= 0.0 or d2 < 1e-6:
        return None
    k = 2.0 * gy / d2  # the circle through the origin, tangent to x, and through the goal
    if abs(k) > p.max_curvature_per_m:
        return None
    if abs(k) > 1e-9 and 2.0 * np.arctan2(abs(gy), gx) / abs(k) > p.look_ahead_m:
        return None
    length = float(np.sqrt(d2)) if abs(k) < 1e-9 else float(2.0 * np.arctan2(abs(gy), gx) / abs(k))
    k = 0.0 if abs(k) < 1e-9 else float(k)
    ds = p.cell_size_m / 2
    s = np.linspace(0.0, p.look_ahead_m, int(np.ceil(p.look_ahead_m / ds)) + 1)
    return Arc(k, 1, k * p.look_ahead_m, arc_pose(k, s)), length


def closest_approach(
    arc: Arc, pose_xy_yaw: np.ndarray, goal_xy: np.ndarray, params: GestaltParams = GestaltParams()
) -> float | None:
    """Near the goal (``capture_distance_m``): how far to drive along ``arc`` to pass closest to the goal, at
    least ``min_drive_m``, at most ``capture_distance_m`` (a driving arc only). None when the goal is farther or
    the arc is a point turn."""
    p = params
    x, y, yaw = (float(v) for v in pose_xy_yaw)
    goal = np.asarray(goal_xy, dtype=float)
    if arc.direction == 0 or np.hypot(goal[0] - x, goal[1] - y) > p.capture_distance_m:
        return None
    s = np.linspace(p.min_drive_m, p.capture_distance_m, 48)
    rel = arc_pose(arc.curvature_per_m, arc.direction * s)
    c, sn = np.cos(yaw), np.sin(yaw)
    d = np.hypot(x + c * rel[:, 0] - sn * rel[:, 1] - goal[0], y + sn * rel[:, 0] + c * rel[:, 1] - goal[1])
    return float(s[int(np.argmin(d))])


@dataclass(frozen=True)
class _Footprint:
    """Rover-frame sample points covering each arc's swept footprint, and the arc length at which each is reached.

    The rover is a rectangle (``rover_half_length_m`` x ``rover_half_width_m``) carried along the arc's poses (a
    point turn: rotated in place); samples lie on a ``cell_size_m / 2`` lattice, each with the least arc length
    at which the rectangle covers it. ``core_distance_m`` is the same for the smaller core rectangle
    (``core_half_length_m`` x ``core_half_width_m``) that decides vetoes: goodness already grows every obstacle
    (by up to the patch radius), so the core is the wheels' envelope plus a margin, less that growth.
    """

    points_xy: np.ndarray  # (n_arcs, n_samples, 2)
    distance_m: np.ndarray  # (n_arcs, n_samples); inf for padding
    core_distance_m: np.ndarray  # (n_arcs, n_samples); inf where the core never covers the sample


def _swept(poses: np.ndarray, s: np.ndarray, half_length: float, half_width: float, step: float):
    """Lattice points (rover frame at the start) covered by a rectangle carried through ``poses``, with the least
    ``s`` at which each is covered."""
    gx = np.arange(-half_length, half_length + 1e-9, step / 2)
    gy = np.arange(-half_width, half_width + 1e-9, step / 2)
    rx, ry = (a.ravel() for a in np.meshgrid(gx, gy, indexing="ij"))
    c, sn = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    wx = poses[:, 0:1] + c * rx - sn * ry
    wy = poses[:, 1:2] + sn * rx + c * ry
    key_x = np.rint(wx / step).astype(np.int64).ravel()
    key_y = np.rint(wy / step).astype(np.int64).ravel()
    dist = np.broadcast_to(s[:, None], wx.shape).ravel()
    order = np.lexsort((dist, key_y, key_x))
    kx, ky, d = key_x[order], key_y[order], dist[order]
    first = np.ones(len(kx), bool)
    first[1:] = (kx[1:] != kx[:-1]) | (ky[1:] != ky[:-1])
    return np.stack([kx[first] * step, ky[first] * step], axis=-1), d[first]


def footprints(arc_list: list[Arc], params: GestaltParams) -> _Footprint:
    p = params
    step = p.cell_size_m / 2
    per_arc = []
    for arc in arc_list:
        poses = arc.poses_xy_yaw
        if arc.direction == 0:
            # a point turn reaches its whole footprint at once (a token 1 cm of "distance" marks the cells its
            # corners sweep beyond the rectangle it stands on)
            s = np.linspace(0.0, 0.01, len(poses))
        else:
            s = np.linspace(0.0, p.look_ahead_m, len(poses))  # poses are evenly spaced in arc length
        pts, dist = _swept(poses, s, p.rover_half_length_m, p.rover_half_width_m, step)
        core_pts, core_dist = _swept(poses, s, p.core_half_length_m, p.core_half_width_m, step)
        # core samples are lattice points of the footprint too: look their distances up by lattice key
        key = {(int(round(x / step)), int(round(y / step))): d for (x, y), d in zip(core_pts, core_dist, strict=True)}
        cd = np.array([key.get((int(round(x / step)), int(round(y / step))), np.inf) for x, y in pts])
        per_arc.append((pts, dist, cd))
    size = max(len(d) for _, d, _ in per_arc)
    points = np.zeros((len(arc_list), size, 2))
    dist = np.full((len(arc_list), size), np.inf)
    core = np.full((len(arc_list), size), np.inf)
    for a, (pts, d, c) in enumerate(per_arc):
        points[a, : len(d)], dist[a, : len(d)], core[a, : len(d)] = pts, d, c
    return _Footprint(points, dist, core)


# ----------------------------------------------------------------------------------------------------------------
# Step 3: traversability votes
# ----------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ArcVotes:
    """Traversability votes of all arcs (paper: "a set of traversability votes for all arcs")."""

    vote: np.ndarray  # (n_arcs,) weighted mean goodness over the swept footprint, in [0, 1]; 0 where vetoed
    vetoed: np.ndarray  # (n_arcs,) bool: an unknown or impassable cell on the near part
    cells: np.ndarray  # (n_arcs, n, n) arc length (m) at which the footprint first covers each window cell; inf
    # (n_arcs,) lowest goodness the footprint's core meets on the near part, beyond where the rover stands now
    # (unknown cells as in ``vote``); the arbiter prefers arcs whose wheels stay off doubtful ground. None: not
    # computed (counts as 1).
    worst: np.ndarray | None = None


def vote_arcs(
    window: GoodnessWindow,
    pose_xy_yaw: np.ndarray,
    arc_list: list[Arc],
    params: GestaltParams = GestaltParams(),
    footprint: _Footprint | None = None,
) -> ArcVotes:
    """Step 3: per arc, the weighted mean goodness of the cells its swept footprint covers.

    A cell's weight is ``exp(-s / weight_decay_m)`` with ``s`` the arc length at which the footprint first reaches
    it (paper: "nearby cells given higher weight"). Unknown cells count ``unknown_goodness``, except those reaching
    within ``assume_safe_radius_m`` of the rover, which it is standing on: they count as benign. An unknown or
    impassable cell on the near part (arc length up to ``near_distance_m``) of the footprint's core vetoes the arc
    (vote 0); the core is the footprint shrunk by the patch radius (see ``_Footprint``).
    """
    p = params
    fp = footprint if footprint is not None else footprints(arc_list, p)
    x, y, yaw = (float(v) for v in pose_xy_yaw)
    c, s = np.cos(yaw), np.sin(yaw)
    world_x = x + c * fp.points_xy[..., 0] - s * fp.points_xy[..., 1]
    world_y = y + s * fp.points_xy[..., 0] + c * fp.points_xy[..., 1]
    n_arcs = len(arc_list)
    n0, n1 = window.shape
    i, j, inside = window.cell_index(np.stack([world_x.reshape(-1), world_y.reshape(-1)], axis=1))
    flat = (np.repeat(np.arange(n_arcs), fp.points_xy.shape[1]) * n0 + i.clip(0, n0 - 1)) * n1 + j.clip(0, n1 - 1)
    dist = np.where(inside, fp.distance_m.reshape(-1), np.inf)
    first = np.full(n_arcs * n0 * n1, np.inf)
    np.minimum.at(first, flat, dist)
    first_core = np.full(n_arcs * n0 * n1, np.inf)
    core_dist = np.where(inside, fp.core_distance_m.reshape(-1), np.inf)
    core = np.isfinite(core_dist)
    np.minimum.at(first_core, flat[core], core_dist[core])
    first = first.reshape(n_arcs, n0, n1)
    first_core = first_core.reshape(n_arcs, n0, n1)
    # goodness as the votes see it: unknown -> unknown_goodness, or benign under the rover
    g = window.goodness
    unknown = np.isnan(g)
    centres = window.cell_centres_xy()
    reach = p.assume_safe_radius_m + p.cell_size_m / np.sqrt(2.0)  # cell centre within radius + half a diagonal
    under_rover = np.hypot(centres[..., 0] - x, centres[..., 1] - y) <= reach
    g_vote = np.where(unknown, np.where(under_rover, 1.0, p.unknown_goodness), g)
    bad = (unknown & ~under_rover) | (g <= p.impassable_goodness)
    vetoed = ((first_core <= p.near_distance_m) & bad[None]).any(axis=(1, 2))
    covered = np.isfinite(first)
    w = np.where(covered, np.exp(-np.where(covered, first, 0.0) / p.weight_decay_m), 0.0)
    total = w.sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        vote = np.where(total > 0, (w * g_vote[None]).sum(axis=(1, 2)) / total, 0.0)
    vetoed |= total <= 0
    near = (first_core > 0.0) & (first_core <= p.near_distance_m)  # new ground only: not where it stands now
    worst = np.where(near, g_vote[None], np.inf).min(axis=(1, 2))
    worst = np.where(np.isfinite(worst), worst, 1.0)
    return ArcVotes(np.where(vetoed, 0.0, vote), vetoed, first, np.where(vetoed, 0.0, worst))
