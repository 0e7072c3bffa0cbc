"""Step 4a of GESTALT: the waypoint input to the arbiter as a path-cost field to the goal over the goodness window
(8-connected Dijkstra, :func:`cost_to_go`), as the MER flight software gained in 2006 (Carsten et al. 2007).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from nav.gestalt.map import GoodnessWindow
from nav.gestalt.params import GestaltParams


@dataclass(frozen=True)
class CostToGo:
    """Cost (metres, weighted) of the best path from each window cell to the goal; inf where blocked or cut off.

    Cells beyond the window are unknown to the map: a path leaving the window is charged its straight-line
    distance from the edge cell to the goal, so the field is a lower bound there and exact (on the grid) inside.
    """

    origin_cell: tuple[int, int]
    cell_size_m: float
    cost: np.ndarray  # (n, n)
    blocked: np.ndarray  # (n, n) bool: impassable cells grown by the footprint core

    def at(self, xy: np.ndarray) -> np.ndarray:
        """Bilinear cost at world points (N, 2) from the four surrounding cell centres; if any of them is
        infinite, the nearest cell's value. inf outside the window."""
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        n0, n1 = self.cost.shape
        u = xy[:, 0] / self.cell_size_m - 0.5 - self.origin_cell[0]
        v = xy[:, 1] / self.cell_size_m - 0.5 - self.origin_cell[1]
        i0 = np.floor(u).astype(np.int64)
        j0 = np.floor(v).astype(np.int64)
        fu, fv = u - i0, v - j0
        out = np.full(len(xy), np.inf)
        inside = (i0 >= 0) & (i0 < n0 - 1) & (j0 >= 0) & (j0 < n1 - 1)
        i, j, a, b = i0[inside], j0[inside], fu[inside], fv[inside]
        c00, c10 = self.cost[i, j], self.cost[i + 1, j]
        c01, c11 = self.cost[i, j + 1], self.cost[i + 1, j + 1]
        with np.errstate(invalid="ignore"):
            bil = (1 - a) * (1 - b) * c00 + a * (1 - b) * c10 + (1 - a) * b * c01 + a * b * c11
        near = self.cost[i + np.rint(a).astype(np.int64), j + np.rint(b).astype(np.int64)]
        out[inside] = np.where(np.isfinite(bil), bil, near)
        return out


def _disc(radius_cells: float) -> np.ndarray:
    r = int(np.floor(radius_cells + 1e-9))
    o = np.arange(-r, r + 1)
    return (o[:, None] ** 2 + o[None, :] ** 2 <= radius_cells**2 + 1e-9).astype(np.uint8)


def cost_to_go(
    window: GoodnessWindow,
    pose_xy_yaw: np.ndarray,
    goal_xy: np.ndarray,
    params: GestaltParams = GestaltParams(),
    visits: np.ndarray | None = None,
) -> CostToGo:
    """Waypoint input for the arbiter: the cost of the best grid path (8-connected, Dijkstra) to the goal.

    The goal's vote in the paper is geometric; driving "towards the goal" then runs the rover into every pocket
    between rocks and back out again. Later MER flight software (R9.2, Carsten et al. 2007) added a global
    path-cost field for exactly this: arcs are judged by how much they lower the cost still to go. A step between
    cells costs its length times ``1 + goodness_cost * (1 - goodness)``; unknown cells cost ``unknown_cost`` per
    metre (optimistic: unseen ground may be clear); impassable cells, grown by the footprint core's half-width
    plus a margin (``core_half_width_m + path_margin_m``) so that the path only uses gaps the arcs can use, are
    walls.
    Unknown cells within ``assume_safe_radius_m`` of the rover count as benign, as for the votes; other unknown
    cells the arcs could reach within ``near_distance_m`` are walls (the vetoes refuse them). ``visits`` (window
    shaped) counts the cycles the rover has stood near each cell; each adds ``visit_cost`` per metre, so a rover
    dithering between two places makes both dearer until another way wins.
    """
    p = params
    g = window.goodness
    n0, n1 = g.shape
    cs = window.cell_size_m
    x, y = float(pose_xy_yaw[0]), float(pose_xy_yaw[1])
    goal = np.asarray(goal_xy, dtype=float)
    impassable = g <= p.impassable_goodness
    # an obstacle seen only from afar may be stereo noise (elevation error grows with range squared): costly, not
    # a wall, until a nearer look confirms it
    far = impassable & (window.range_m > p.certain_range_m) if window.range_m is not None else np.zeros_like(impassable)
    wall = (impassable & ~far).astype(np.uint8)
    core = p.core_half_width_m + p.path_margin_m
    blocked = cv2.dilate(wall, _disc(core / cs)).astype(bool) if core > 0 else wall.astype(bool)
    centres = window.cell_centres_xy()
    under_rover = np.hypot(centres[..., 0] - x, centres[..., 1] - y) <= p.assume_safe_radius_m
    unknown = np.isnan(g)
    g0 = np.nan_to_num(g)
    factor = 1.0 + p.goodness_cost * (1.0 - g0) + p.doubt_cost * np.clip(1.0 - g0 / p.doubt_goodness, 0.0, 1.0)
    factor = np.where(unknown, np.where(under_rover, 1.0, p.unknown_cost), factor)
    factor = np.where(far, p.far_obstacle_cost, factor)
    if visits is not None:  # ground the rover has stood on many times: somewhere else, please
        factor = factor + p.visit_cost * visits
    # keep clear of walls where there is room: shortest paths otherwise graze them at the veto's margin
    if p.clearance_cost > 0 and wall.any():
        dist = cv2.distanceTransform((1 - wall).astype(np.uint8), cv2.DIST_L2, 5) * cs
        factor = factor + p.clearance_cost * np.clip(1.0 - dist / p.clearance_range_m, 0.0, 1.0)
    # unknown ground the arcs' vetoes would refuse (near the rover, not under it) is a wall for the path too, or the
    # field would lead into what the arcs cannot enter (a rock's shadow) and the rover would dither in front of it
    near_rover = np.hypot(centres[..., 0] - x, centres[..., 1] - y) <= p.near_distance_m + p.core_half_length_m
    blocked = blocked | (unknown & near_rover & ~under_rover)
    factor = np.where(blocked, np.inf, factor)
    idx = np.arange(n0 * n1).reshape(n0, n1)
    rows, cols, wts = [], [], []
    for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
        a = idx[max(0, -di) : n0 - max(0, di), max(0, -dj) : n1 - max(0, dj)]
        b = idx[max(0, di) : n0 + min(0, di), max(0, dj) : n1 + min(0, dj)]
        fa = factor.reshape(-1)[a.reshape(-1)]
        fb = factor.reshape(-1)[b.reshape(-1)]
        w = 0.5 * (fa + fb) * cs * np.hypot(di, dj)
        ok = np.isfinite(w)
        rows.append(a.reshape(-1)[ok])
        cols.append(b.reshape(-1)[ok])
        wts.append(w[ok])
    # a virtual source joined to the goal cell (goal inside the window) or to every open edge cell (outside)
    src = n0 * n1
    gi, gj, inside = window.cell_index(goal[None])
    inside = bool(inside[0]) and 0 < gi[0] < n0 - 1 and 0 < gj[0] < n1 - 1
    if inside:
        seeds = np.array([idx[gi[0], gj[0]]])
        seed_cost = np.array([1e-6])
    else:
        edge = np.zeros((n0, n1), bool)
        edge[[0, -1], :] = True
        edge[:, [0, -1]] = True
        edge &= ~blocked
        seeds = idx[edge]
        seed_cost = np.maximum(np.hypot(*(centres[edge] - goal).T), 1e-6)
    rows.append(np.full(len(seeds), src))
    cols.append(seeds)
    wts.append(seed_cost)
    graph = csr_matrix((np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))), shape=(src + 1, src + 1))
    dist = dijkstra(graph, directed=False, indices=src)[:src].reshape(n0, n1)
    return CostToGo(window.origin_cell, cs, dist, blocked)
