"""GESTALT autonomous navigation in the simulator (MER autonav, seed 001 section 4; REFERENCE.md section 3.3).

Each cycle: hazcam stereo pair -> SAD stereo range image -> points in the world frame *via the onboard pose*
(never the truth) -> goodness map update -> arc votes + waypoint votes -> the winning arc is driven for
``step_m`` (near the goal: the arc through the goal, all the way) -> stop, image, repeat; until the onboard pose is
within ``tolerance_m`` of the goal or no arc is safe.

Range points kept for the map: within ``MAX_RANGE_M`` (hazcam stereo is too coarse beyond) and outside the rover's
own plan-view box (the hazcams see the front wheels). After a backward drive the rear hazcam pair is imaged as well,
so the rover sees the ground it backs into. No safe arc: retrace the last drive and look again.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from nav.camera import transform_points
from nav.gestalt import Arc as GestaltArc
from nav.gestalt import GestaltParams, GestaltPlanner, arc_pose
from nav.stereo import StereoParams, range_image
from rover_sim.sim.drive import Arc, Primitive, Straight, TurnInPlace

if TYPE_CHECKING:
    from rover_sim.mission.pipeline import Mission
    from rover_sim.mission.scenario import AutonavCmd

HAZCAM = "hazcam_front"
REAR_HAZCAM = "hazcam_rear"  # imaged too while the rover is backing up (it does not otherwise look behind)
MAX_BACKTRACKS = 12  # retraced steps allowed per autonav command before giving up
# Hazcam look-ahead on MER: 3-4 m useful. At 256^2 (10 cm baseline) the disparity at 3.5 m is ~2 px and
# elevation errors there reach 10-20 cm, as big as the steps GESTALT must see; farther points only add false rocks.
MAX_RANGE_M = 3.5
# The rover's own wheels are in the hazcams' view (front wheels, more so when steered): points inside the rover's
# plan-view box (rover frame, |x| and |y| below these) are the vehicle, not terrain.
SELF_MASK_HALF_LENGTH_M = 0.85
SELF_MASK_HALF_WIDTH_M = 0.8


@dataclass
class AutonavStats:
    cycles: int = 0
    cycle_ms: list[float] = field(default_factory=list)  # stereo + map + votes
    outcome: str = ""
    backtracks: int = 0
    last_decision: object = None  # nav.gestalt.Decision of the last cycle (for inspection)


def primitive_for(arc: GestaltArc, step_m: float) -> Primitive:
    """The drive command for a GESTALT arc: point turn, straight or Ackermann arc, ``step_m`` long."""
    if arc.direction == 0:
        return TurnInPlace(arc.turn_rad)
    if abs(arc.curvature_per_m) < 1e-6:
        return Straight(arc.direction * step_m)
    return Arc(1.0 / arc.curvature_per_m, arc.direction * step_m)


def reverse_of(prim: Primitive) -> Primitive:
    """The primitive that retraces ``prim`` (drive back along the same arc, or turn back)."""
    if isinstance(prim, TurnInPlace):
        return TurnInPlace(-prim.angle_rad)
    if isinstance(prim, Arc):
        return Arc(prim.radius_m, -prim.distance_m)
    return Straight(-prim.distance_m)


def terrain_points(points_rover: np.ndarray) -> np.ndarray:
    """Range points worth mapping: within ``MAX_RANGE_M`` and outside the rover's own plan-view box."""
    xy = points_rover[:, :2]
    own = (np.abs(xy[:, 0]) < SELF_MASK_HALF_LENGTH_M) & (np.abs(xy[:, 1]) < SELF_MASK_HALF_WIDTH_M)
    return points_rover[(np.hypot(xy[:, 0], xy[:, 1]) < MAX_RANGE_M) & ~own]


def _drives_backward(prim: Primitive) -> bool:
    return isinstance(prim, Straight | Arc) and prim.distance_m < 0


def _heading(R: np.ndarray) -> float:
    return float(math.atan2(R[1, 0], R[0, 0]))


def run_autonav(mission: Mission, cmd: AutonavCmd, params: GestaltParams | None = None) -> AutonavStats:
    planner = GestaltPlanner(params or GestaltParams())
    stereo = StereoParams()
    stats = AutonavStats()
    mission.autonav_stats = stats
    rig = mission.renderer.rig(HAZCAM)  # body-fixed, calibrated once
    rear_rig = mission.renderer.rig(REAR_HAZCAM)
    mission.rec.log_camera(HAZCAM, rig, mission.sim.time_s)
    goal = np.array([cmd.x_m, cmd.y_m])
    history: list[Primitive] = []
    backing = False  # the last drive was backward: look behind as well
    for _ in range(cmd.max_cycles):
        pose = mission.onboard.pose
        if np.linalg.norm(goal - pose.position_xyz_m[:2]) <= cmd.tolerance_m:
            stats.outcome = "goal reached (onboard pose)"
            mission._event(f"autonav: {stats.outcome}")
            return stats
        frame = mission.renderer.render_pair(HAZCAM)
        rear = mission.renderer.render_pair(REAR_HAZCAM) if backing else None
        t0 = time.perf_counter()
        ri = range_image(frame.left, frame.right, rig, stereo)
        pts = terrain_points(ri.points_rover_m())
        if rear is not None:
            rear_ri = range_image(rear.left, rear.right, rear_rig, stereo)
            pts = np.vstack([pts, terrain_points(rear_ri.points_rover_m())])
        T = pose.as_matrix()
        pts_world = transform_points(T, pts)
        yaw = _heading(T[:3, :3])
        decision = planner.step(pts_world, np.array([T[0, 3], T[1, 3], yaw]), goal)
        stats.cycle_ms.append((time.perf_counter() - t0) * 1e3)
        stats.cycles += 1
        stats.last_decision = decision
        _log_cycle(mission, frame, ri, pts_world, decision, planner.arcs, T)
        if decision.arc is None:
            # Boxed in: retrace the last step (ground already driven over is known safe) and look again with
            # the obstacles now in the map; give up after MAX_BACKTRACKS.
            if not history or stats.backtracks >= MAX_BACKTRACKS:
                stats.outcome = "no safe arc"
                mission._event(f"autonav stopped: {decision.reason}", "WARN")
                return stats
            stats.backtracks += 1
            mission._event(f"autonav cycle {stats.cycles}: no safe arc, backtracking", "WARN")
            back = reverse_of(history.pop())
            mission._primitive(back)
            backing = _drives_backward(back)
            continue
        mission._event(f"autonav cycle {stats.cycles}: {decision.reason}")
        dist = float(np.linalg.norm(goal - T[:2, 3]))
        step = decision.drive_m if decision.drive_m is not None else min(cmd.step_m, max(dist, 0.35))
        prim = primitive_for(decision.arc, step)
        mission._primitive(prim)
        history.append(prim)
        backing = _drives_backward(prim)
        if mission.vo is not None:
            mission._vo_update()
    stats.outcome = "cycle budget used up"
    mission._event(f"autonav: {stats.outcome}", "WARN")
    return stats


def _log_cycle(
    mission: Mission, frame, ri, pts_world: np.ndarray, decision, arcs: list[GestaltArc], T_world_rover: np.ndarray
) -> None:
    rec, t, step = mission.rec, mission.sim.time_s, mission.step
    rec.log_stereo_images(HAZCAM, t, step, frame.left, frame.right, ri.disparity_px)
    rec.log_points("stereo", t, step, pts_world)
    w = decision.window
    g = w.goodness.ravel()
    xy = w.cell_centres_xy().reshape(-1, 2)
    z = np.nan_to_num(w.elevation_m.ravel(), nan=T_world_rover[2, 3] - 0.5)
    rec.log_goodness(t, step, xy, z, g, w.cell_size_m)
    polylines, votes = [], []
    for i, arc in enumerate(arcs):
        local = arc.poses_xy_yaw[:, :2] if arc.direction != 0 else arc_pose(0.0, np.zeros(2))[:, :2]
        world = local @ T_world_rover[:2, :2].T + T_world_rover[:2, 3]
        polylines.append(np.column_stack([world, np.full(len(world), T_world_rover[2, 3] - 0.45)]))
        votes.append(None if decision.votes.vetoed[i] else float(decision.votes.vote[i]))
    rec.log_arcs(t, step, polylines, votes, decision.arc_index)
