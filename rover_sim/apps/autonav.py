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

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np

from nav.gestalt import Arc as GestaltArc
from nav.gestalt import arc_pose
from rover_sim.runtime.onboard import PlanCycle
from rover_sim.sim.drive import Arc, Primitive, Straight, TurnInPlace
from rover_sim.world.clock import AUTONAV_CYCLE_S, IMAGE_PAIR_ACQUIRE_S

# A sol's drive logs every cycle's hazcam pair but the cycle's detail (depth image, stereo points, goodness map,
# arc votes: ~100 kB of the ~125 kB a cycle) only every SOL_DETAIL_EVERY-th cycle and on boxed-in cycles, so a
# kilometre with a thousand-odd cycles stays under 150 MB; the viewer shows the latest detail logged.
SOL_DETAIL_EVERY = 4

if TYPE_CHECKING:
    from rover_sim.io.recorder_protocol import Recorder
    from rover_sim.runtime.onboard import Onboard, VoStep
    from rover_sim.scenario.commands import AutonavCmd
    from rover_sim.scenario.schema import Scenario
    from rover_sim.sim.physics import RoverSim
    from rover_sim.world.observation import Observation
    from rover_sim.world.world import World

HAZCAM = "hazcam_front"
REAR_HAZCAM = "hazcam_rear"  # imaged too while the rover is backing up (it does not otherwise look behind)
MAX_BACKTRACKS = 12  # retraced steps allowed per autonav command before giving up


class AutonavRunner(Protocol):
    """What autonav uses of the runner (:class:`rover_sim.runtime.runner.Mission` is one): it drives, images and logs
    through these and leaves its statistics in ``autonav_stats``."""

    sc: Scenario
    world: World
    onboard: Onboard
    rec: Recorder
    step: int
    autonav_stats: AutonavStats | None

    @property
    def sim(self) -> RoverSim: ...

    def execute(self, prim: Primitive) -> None: ...

    def vo_update(self) -> VoStep | None: ...

    def notify_images(self, obs: Observation) -> None: ...

    def event(self, text: str, level: str = "INFO") -> None: ...


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


def _drives_backward(prim: Primitive) -> bool:
    return isinstance(prim, Straight | Arc) and prim.distance_m < 0


def run_autonav(mission: AutonavRunner, cmd: AutonavCmd) -> AutonavStats:
    """Drive to the waypoint of ``cmd`` with GESTALT on the onboard pose (the loop in the module docstring)."""
    onboard = mission.onboard
    onboard.start_planning()
    stats = AutonavStats()
    mission.autonav_stats = stats
    rig = mission.world.calibrate(HAZCAM)  # body-fixed, calibrated once
    mission.world.calibrate(REAR_HAZCAM)
    mission.rec.log_camera(HAZCAM, rig, mission.sim.time_s)
    goal = np.array([cmd.x_m, cmd.y_m])
    history: list[Primitive] = []
    backing = False  # the last drive was backward: look behind as well
    for _ in range(cmd.max_cycles):
        pose = onboard.pose
        if np.linalg.norm(goal - pose.position_xyz_m[:2]) <= cmd.tolerance_m:
            stats.outcome = "goal reached (onboard pose)"
            mission.event(f"autonav: {stats.outcome}")
            return stats
        cameras = (HAZCAM, REAR_HAZCAM) if backing else (HAZCAM,)
        frames = {c: mission.world.render(c) for c in cameras}
        obs = mission.world.observation_with([], [], frames)
        mission.notify_images(obs)
        cycle = onboard.plan(obs, goal, cameras)
        mission.world.charge("computing", AUTONAV_CYCLE_S - IMAGE_PAIR_ACQUIRE_S)  # the cycle time includes a pair
        decision = cycle.decision
        stats.cycle_ms.append(cycle.ms)
        stats.cycles += 1
        stats.last_decision = decision
        detail = mission.sc.sol is None or decision.arc is None or (stats.cycles - 1) % SOL_DETAIL_EVERY == 0
        _log_cycle(mission, obs, cycle, onboard.planner.arcs, detail)  # type: ignore[union-attr]
        if decision.arc is None:
            # Boxed in: retrace the last step (ground already driven over is known safe) and look again with
            # the obstacles now in the map; give up after MAX_BACKTRACKS.
            if not history or stats.backtracks >= MAX_BACKTRACKS:
                stats.outcome = "no safe arc"
                mission.event(f"autonav stopped: {decision.reason}", "WARN")
                return stats
            stats.backtracks += 1
            mission.event(f"autonav cycle {stats.cycles}: no safe arc, backtracking", "WARN")
            back = reverse_of(history.pop())
            mission.execute(back)
            backing = _drives_backward(back)
            continue
        mission.event(f"autonav cycle {stats.cycles}: {decision.reason}")
        T = cycle.T_world_rover
        dist = float(np.linalg.norm(goal - T[:2, 3]))
        drive_m = getattr(decision, "drive_m", None)
        step = drive_m if drive_m is not None else min(cmd.step_m, max(dist, 0.35))
        prim = primitive_for(decision.arc, step)
        mission.execute(prim)
        history.append(prim)
        backing = _drives_backward(prim)
        if onboard.vo is not None:
            mission.vo_update()
    stats.outcome = "cycle budget used up"
    mission.event(f"autonav: {stats.outcome}", "WARN")
    return stats


def _log_cycle(
    mission: AutonavRunner, obs: Observation, cycle: PlanCycle, arcs: list[GestaltArc], detail: bool = True
) -> None:
    """The cycle's rectified pair; with ``detail`` also its range (depth image, points), goodness map and votes."""
    rec, t, step = mission.rec, mission.sim.time_s, mission.step
    pair = mission.onboard.rectified(obs, HAZCAM)
    T_world_rover = cycle.T_world_rover
    decision = cycle.decision
    disparity = cycle.range_image.disparity_px if detail else None
    rec.log_stereo_images(HAZCAM, t, step, pair.left_u8, pair.right_u8, disparity)
    if not detail:
        return
    rec.log_points("stereo", t, step, cycle.points_world)
    w = getattr(decision, "window", None)
    if w is not None:
        g = w.goodness.ravel()
        xy = w.cell_centres_xy().reshape(-1, 2)
        z = np.nan_to_num(w.elevation_m.ravel(), nan=T_world_rover[2, 3] - 0.5)
        rec.log_goodness(t, step, xy, z, g, w.cell_size_m)
    votes_obj = getattr(decision, "votes", None)
    polylines, votes = [], []
    for i, arc in enumerate(arcs):
        local = arc.poses_xy_yaw[:, :2] if arc.direction != 0 else arc_pose(0.0, np.zeros(2))[:, :2]
        world = local @ T_world_rover[:2, :2].T + T_world_rover[:2, 3]
        polylines.append(np.column_stack([world, np.full(len(world), T_world_rover[2, 3] - 0.45)]))
        if votes_obj is None:
            votes.append(None)
        else:
            votes.append(None if votes_obj.vetoed[i] else float(votes_obj.vote[i]))
    rec.log_arcs(t, step, polylines, votes, getattr(decision, "arc_index", None))
