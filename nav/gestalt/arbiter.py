"""Step 4 of GESTALT (Maimone et al. 2005, section 4.2): the waypoint votes, the arbiter ("an arbiter, which also
takes input from waypoints") and one whole cycle, :class:`GestaltPlanner` (map update, goodness, votes,
arbitration).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nav.gestalt.arcs import Arc, ArcVotes, arc_pose, arcs, closest_approach, footprints, goal_arc, vote_arcs
from nav.gestalt.map import GoodnessMap, GoodnessWindow
from nav.gestalt.params import GestaltParams
from nav.gestalt.path_cost import CostToGo, cost_to_go

# ----------------------------------------------------------------------------------------------------------------
# Step 4: waypoint votes and arbiter
# ----------------------------------------------------------------------------------------------------------------


def waypoint_votes(
    arc_list: list[Arc],
    pose_xy_yaw: np.ndarray,
    goal_xy: np.ndarray,
    params: GestaltParams = GestaltParams(),
    cost: CostToGo | None = None,
) -> np.ndarray:
    """Step 4a: how much each arc helps reach the goal (paper: the arbiter "takes input from waypoints"), in [0, 1].

    Judged where the rover will be after this cycle's drive (``step_distance_m`` along the arc; a point turn's full
    turn): (a) progress, the distance to the goal gained over the distance driven (-1..1; 0 for point turns), and
    (b) heading, how well the rover then faces the way on (-1..1); weighted by ``progress_weight`` and
    ``heading_weight`` and mapped to [0, 1].

    Without ``cost`` (or when it walls the rover in: no arc ends on a cell with a way to the goal) distances are
    straight lines and heading is the cosine of the angle to the goal's bearing.
    With a :class:`CostToGo` field, distance is the path cost still to go (so a detour round a rock is progress)
    and heading is the progress made by going on forward to ``heading_lookahead_m`` (a forward arc along its circle,
    a point turn straight on after the turn, a backward arc straight ahead of the nose from its end; -1 into a wall).
    """
    p = params
    x, y, yaw = (float(v) for v in pose_xy_yaw)
    goal = np.asarray(goal_xy, dtype=float)
    ends = np.array(
        [
            a.poses_xy_yaw[-1] if a.direction == 0 else arc_pose(a.curvature_per_m, a.direction * p.step_distance_m)
            for a in arc_list
        ]
    )
    c, s = np.cos(yaw), np.sin(yaw)
    ex = x + c * ends[:, 0] - s * ends[:, 1]
    ey = y + s * ends[:, 0] + c * ends[:, 1]
    eyaw = yaw + ends[:, 2]
    driven = np.array([0.0 if a.direction == 0 else p.step_distance_m for a in arc_list])
    d_end = np.hypot(goal[0] - ex, goal[1] - ey)
    bearing = np.arctan2(goal[1] - ey, goal[0] - ex)
    geometric_heading = np.where(d_end > 1e-6, np.cos(bearing - eyaw), 1.0)
    c_end = cost.at(np.stack([ex, ey], axis=1)) if cost is not None else None
    if c_end is None or not np.isfinite(c_end).any():
        # no field, or one that walls the rover in (it sees no way out from here): go by the bearing, the vetoes
        # keep it safe, and the next images may open a way
        d_now = np.hypot(goal[0] - x, goal[1] - y)
        progress = np.where(driven > 0, (d_now - d_end) / np.maximum(driven, 1e-9), 0.0)
        heading = geometric_heading
    else:
        c_now = float(cost.at(np.array([[x, y]]))[0])
        if not np.isfinite(c_now):  # standing in a (falsely) blocked cell: judge against the best way out
            finite = c_end[np.isfinite(c_end)]
            c_now = float(finite.min()) + p.step_distance_m if finite.size else 0.0
        with np.errstate(invalid="ignore"):
            progress = np.where(driven > 0, (c_now - c_end) / np.maximum(driven, 1e-9), 0.0)
        progress = np.where(np.isfinite(c_end), np.clip(progress, -1.0, 1.0), -1.0)
        # heading: the progress the rover makes going on forward from where the arc leaves it, up to
        # heading_lookahead_m: a forward arc goes on along its circle, a point turn straight on after the turn, and a
        # backward arc straight ahead of the rover's nose from the end of its step (it faces the way on only if its
        # front, where its hazcams look, points there; backing on along the circle would score a blind reverse
        # drive as well-aimed and lead the rover metres backwards through ground it has not looked at)
        look = p.heading_lookahead_m
        far = np.array([_look_ahead_pose(a, p.step_distance_m, look) for a in arc_list])
        c_far = cost.at(np.stack([x + c * far[:, 0] - s * far[:, 1], y + s * far[:, 0] + c * far[:, 1]], axis=1))
        with np.errstate(invalid="ignore"):
            # measured from where the look-ahead starts: here, or a backward arc's end
            c_from = np.where([a.direction < 0 for a in arc_list], c_end, c_now)
            heading = np.clip((c_from - c_far) / look, -1.0, 1.0)
        heading = np.where(np.isfinite(c_far), heading, -1.0)
        # the goal itself is closer than the look-ahead: face it
        heading = np.where(d_end < look, geometric_heading, heading)
    mix = (p.progress_weight * progress + p.heading_weight * heading) / (p.progress_weight + p.heading_weight)
    return np.clip(0.5 * (1.0 + mix), 0.0, 1.0)


def _look_ahead_pose(a: Arc, step_m: float, look_m: float) -> np.ndarray:
    """Rover-frame point ``look_m`` on from arc ``a`` in the direction the rover then faces (see waypoint_votes)."""
    if a.direction == 0:
        return a.poses_xy_yaw[-1] + [look_m * np.cos(a.turn_rad), look_m * np.sin(a.turn_rad), 0.0]
    if a.direction > 0:
        return arc_pose(a.curvature_per_m, look_m)
    end = arc_pose(a.curvature_per_m, -step_m)
    return end + [look_m * np.cos(end[2]), look_m * np.sin(end[2]), 0.0]


def undoes(arc_list: list[Arc], previous: Arc | None, params: GestaltParams = GestaltParams()) -> np.ndarray:
    """(n_arcs,) bool: the arcs that would take back ``previous`` - the opposite point turn, or the drive back
    along (nearly) the same circle. Dithering between a move and its undo is GESTALT's classic failure."""
    out = np.zeros(len(arc_list), bool)
    if previous is None:
        return out
    for k, a in enumerate(arc_list):
        if previous.direction == 0:
            out[k] = a.direction == 0 and np.sign(a.turn_rad) != np.sign(previous.turn_rad)
        elif a.direction == -previous.direction:
            out[k] = abs(a.curvature_per_m - previous.curvature_per_m) <= params.undo_curvature_per_m
    return out


def arbitrate(
    trav: ArcVotes,
    wp_votes: np.ndarray,
    directions: np.ndarray,
    params: GestaltParams = GestaltParams(),
    undo: np.ndarray | None = None,
) -> tuple[int | None, np.ndarray]:
    """Step 4b, the arbiter: the arc with the best weighted sum of traversability and waypoint votes.

    ``score = traversability_weight * trav + worst_weight * worst + waypoint_weight * wp - penalties``
    (``worst`` the lowest goodness the arc's core meets on its near part); penalties by ``directions`` (+1 forward,
    -1 backward, 0 point turn: ``backward_penalty``, ``point_turn_penalty``) and ``undo_penalty`` for the arcs
    marked in ``undo`` (see :func:`undoes`). Vetoed arcs and arcs voted below ``min_traversability_vote`` are out.
    Returns the winner's index (None when no arc is safe: the rover must stop) and every score (NaN where out).
    """
    p = params
    directions = np.asarray(directions)
    penalty = np.where(directions == 0, p.point_turn_penalty, np.where(directions < 0, p.backward_penalty, 0.0))
    if undo is not None:
        penalty = penalty + np.where(undo, p.undo_penalty, 0.0)
    allowed = ~trav.vetoed & (trav.vote >= p.min_traversability_vote)
    score = p.traversability_weight * trav.vote + p.waypoint_weight * np.asarray(wp_votes) - penalty
    if trav.worst is not None:
        score = score + p.worst_weight * trav.worst
    score = np.where(allowed, score, np.nan)
    if not allowed.any():
        return None, score
    return int(np.nanargmax(score)), score


# ----------------------------------------------------------------------------------------------------------------
# One GESTALT cycle
# ----------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Decision:
    """Everything one cycle decided and why, for the driver and for a logger to draw."""

    arc: Arc | None  # None: no safe arc, stop
    arc_index: int | None
    votes: ArcVotes
    waypoint_votes: np.ndarray
    scores: np.ndarray  # arbiter score per arc, NaN where vetoed or too poor
    window: GoodnessWindow
    reason: str
    cost: CostToGo | None = None  # the path-cost field the waypoint votes used (None: straight-line votes)
    # distance to drive along ``arc`` (the goal capture arc); None: the driver's usual step
    drive_m: float | None = None


class GestaltPlanner:
    """GESTALT: keeps the goodness map between cycles; :meth:`step` runs one cycle."""

    def __init__(self, params: GestaltParams = GestaltParams()) -> None:
        self.params = params
        self.map = GoodnessMap(params)
        self.arcs = arcs(params)
        self._footprint = footprints(self.arcs, params)
        self._directions = np.array([a.direction for a in self.arcs])
        self.previous: Arc | None = None  # the arc chosen last cycle (the driver may overrule: see ``step``)
        self.visits: dict[tuple[int, int], int] = {}  # world cell -> cycles the rover stood within visit_radius_m

    def _visit(self, xy: np.ndarray) -> None:
        cs, r = self.params.cell_size_m, self.params.visit_radius_m
        ix, iy = int(np.floor(xy[0] / cs)), int(np.floor(xy[1] / cs))
        m = int(np.ceil(r / cs))
        for dx in range(-m, m + 1):
            for dy in range(-m, m + 1):
                cx, cy = (ix + dx + 0.5) * cs, (iy + dy + 0.5) * cs
                if np.hypot(cx - xy[0], cy - xy[1]) <= r + 1e-9:
                    self.visits[(ix + dx, iy + dy)] = self.visits.get((ix + dx, iy + dy), 0) + 1

    def visit_window(self, window: GoodnessWindow) -> np.ndarray:
        """The visit counts over ``window`` (window-shaped)."""
        out = np.zeros(window.shape)
        (ox, oy), (n0, n1) = window.origin_cell, window.shape
        for (ix, iy), count in self.visits.items():
            if 0 <= ix - ox < n0 and 0 <= iy - oy < n1:
                out[ix - ox, iy - oy] = count
        return out

    def step(self, points_world: np.ndarray, pose_xy_yaw: np.ndarray, goal_xy: np.ndarray) -> Decision:
        """Update map -> evaluate goodness -> vote -> arbitrate. ``points_world`` (N, 3) may be empty.

        Near the goal (within ``capture_distance_m``, in front of the rover) the arc through the goal itself is
        voted too and, if safe, driven to the goal (``Decision.drive_m``), so the rover stops on the waypoint
        rather than anywhere inside the tolerance.
        """
        p = self.params
        pose = np.asarray(pose_xy_yaw, dtype=float)
        self.map.update(points_world, pose[:2])
        window = self.map.evaluate(pose[:2])
        trav = vote_arcs(window, pose, self.arcs, p, self._footprint)
        field = cost_to_go(window, pose, goal_xy, p, self.visit_window(window)) if p.use_path_cost else None
        self._visit(pose[:2])  # counted from the next cycle on
        wp = waypoint_votes(self.arcs, pose, goal_xy, p, field)
        best, score = arbitrate(trav, wp, self._directions, p, undoes(self.arcs, self.previous, p))
        capture = goal_arc(pose, goal_xy, p)
        if capture is not None:
            arc, length = capture
            v = vote_arcs(window, pose, [arc], p)
            if not v.vetoed[0] and v.vote[0] >= p.min_traversability_vote:
                reason = f"{arc.name} to the goal ({length:.2f} m): traversability {v.vote[0]:.2f}"
                self.previous = arc
                return Decision(arc, None, trav, wp, score, window, reason, field, length)
        if best is None:
            reason = "no safe arc: every arc is vetoed or below min_traversability_vote"
            self.previous = None
            return Decision(None, None, trav, wp, score, window, reason, field)
        arc = self.arcs[best]
        self.previous = arc
        reason = f"{arc.name}: traversability {trav.vote[best]:.2f}, waypoint {wp[best]:.2f}"
        return Decision(arc, best, trav, wp, score, window, reason, field, closest_approach(arc, pose, goal_xy, p))
