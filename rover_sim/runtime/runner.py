"""The pipeline: scenario -> world -> commands -> observations -> onboard stack -> evaluator -> outputs.

It owns nothing the algorithms need to know about (kiss-icp ``pipeline.py`` style): the :class:`World` (physics,
soil, sensors, rendering), the :class:`Onboard` stack (dead reckoning, VO, stereo, GESTALT; fed only
:class:`Observation` objects), the :class:`Evaluator` (the only place truth meets the estimates) and the recorder
(a sink). Autonav (:mod:`rover_sim.apps.autonav`) and rock surveys (:mod:`rover_sim.apps.survey`) drive a
:class:`Mission` through its public methods only.

Per 8 Hz tick (:meth:`Mission.tick`): sensors -> Observation -> onboard dead reckoning -> evaluator (truth beside
the estimates, contacts) -> keep-out check on the onboard pose -> recording.
VO (:meth:`Mission.vo_update`): the rover stops every ``nav.vo_step_m`` of commanded travel, takes a stereo pair
and runs one VO step; an accepted motion replaces the dead-reckoned increment since the previous pair.
A drive of several sols (:meth:`Mission.sleep`): a sol whose budget is spent skips its remaining commands up to the
next ``sleep``, which parks the rover overnight and starts the next sol.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from nav.trajectory import Pose, Trajectory
from rover_sim import interrupts
from rover_sim.errors import PhysicsDiverged, PluginError
from rover_sim.io.recorder_protocol import NullRecorder, Recorder
from rover_sim.io.rut_log import RutLog
from rover_sim.runtime import acceptance
from rover_sim.runtime.acceptance import TALL_ROCK_M
from rover_sim.runtime.evaluator import Evaluator, Metrics, VoStepRecord
from rover_sim.runtime.onboard import Onboard, VoStep, heading_rad
from rover_sim.runtime.plugins import make_planner, make_stereo, make_vo
from rover_sim.runtime.pointing import seek_texture
from rover_sim.runtime.runner_recording import RunRecording
from rover_sim.runtime.sol import BudgetSpent, SolBudget
from rover_sim.scenario.commands import ArcCmd, AutonavCmd, DriveCmd, GotoCmd, MastCmd, SleepCmd, TurnCmd
from rover_sim.scenario.nav_spec import VoSpec
from rover_sim.scenario.schema import Scenario
from rover_sim.sim.drive import Arc, Primitive, Straight, TurnInPlace, execute
from rover_sim.sim.physics import WHEEL_RADIUS_M, RoverSim
from rover_sim.world.clock import VO_STEP_COMPUTE_S
from rover_sim.world.observation import Observation
from rover_sim.world.rover_shape import rover_shape
from rover_sim.world.world import World

GOTO_HEADING_TOLERANCE_RAD = math.radians(5.0)
MAST_SETTLE_S = 2.0  # a mast command waits this long for the servos before imaging


class Halt(Exception):
    """The drive sequence stops (keep-out, slip limit): expected, recorded as the mission outcome."""

    def __init__(self, kind: str, detail: str) -> None:
        self.kind, self.detail = kind, detail
        super().__init__(f"{kind}: {detail}")


def _tilt_deg(R_world_rover: np.ndarray) -> float:
    return math.degrees(math.acos(min(max(float(R_world_rover[2, 2]), -1.0), 1.0)))


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def onboard_for(scenario: Scenario, start_pose: Pose, vo: VoSpec, on_event: Callable[[str], None] | None) -> Onboard:
    """The onboard stack a scenario configures, with the visual odometer ``vo`` (the scenario's own, or another one
    riding along on the same observations)."""
    nav = scenario.nav
    return Onboard(
        start_pose,
        vo=make_vo(vo),
        stereo=make_stereo(nav.stereo),
        planner_factory=lambda: make_planner(nav.planner),
        shape=rover_shape() if vo.shadow_mask else None,
        vo_update=vo.update,
        epipolar_check=nav.epipolar_check,
        on_event=on_event,
        stereo_rotation_sigma_rad=math.radians(scenario.sensors.lens.stereo_rotation_deg),
    )


class Mission(RunRecording):
    """One scenario run. ``run()`` returns :class:`Metrics`; :func:`rover_sim.runtime.run.write_outputs` writes them.
    What it logs to the recorder beyond events and poses is in :class:`RunRecording`."""

    def __init__(
        self,
        scenario: Scenario,
        recorder: Recorder | None = None,
        progress: Callable[[float, str], None] | None = None,
    ) -> None:
        self.sc = scenario
        self.rec: Recorder = recorder or NullRecorder()
        self.rut_log: RutLog | None = None  # deformable runs: the recording's ground tiles (set by log_static)
        self.progress = progress
        self.world = World(scenario)
        nav = scenario.nav
        try:
            self.onboard = onboard_for(scenario, self.world.start_pose(), nav.vo, self.event)
        except BaseException:  # a plugin that does not load, or Ctrl-C: release the renderer's GL context
            self.world.close()
            raise
        self.evaluator = Evaluator(scenario.name, scenario.seed, self._last_goal(), has_vo=self.onboard.vo is not None)
        self.events: list[str] = []
        self.pointing_changes = 0  # texture-seeking mast repointings before VO steps
        self.halted: Halt | None = None
        self.error: str | None = None
        self.interrupted: KeyboardInterrupt | None = None  # Ctrl-C or SIGTERM (errors.Terminated) stopped the run
        self.step = 0
        self.autonav_stats = None  # set by rover_sim.apps.autonav when the scenario uses autonav
        self._autonav_runs: list = []  # the stats of each autonav command run (several in a drive of several sols)
        # public hooks (sinks): exporters, surveys and user code subscribe; none may change the run
        self.vo_listeners: list[Callable[[VoStep, np.ndarray], None]] = []  # (step, T_rover_cam of the pair)
        self.tick_listeners: list[Callable[[Observation, Pose], None]] = []  # (sensor data, truth) at 8 Hz
        self.image_listeners: list[Callable[[Observation, Pose], None]] = []  # every stereo pair the rover takes
        self.vo_reset_listeners: list[Callable[[], None]] = []  # VO starts a new sequence (repointing, a new sol)
        self.extra_timing: dict = {}
        self._wall_s = 0.0
        # a sol's drive: budgets, mission clock, decimated poses and tracks, streamed terrain tiles
        self.sol: SolBudget | None = SolBudget(scenario.sol, self.world.clock) if scenario.sol is not None else None
        self.pose_stride = scenario.sol.pose_stride if scenario.sol is not None else 1
        self._terrain_version = -1

    # ------------------------------------------------------------------ convenience views
    @property
    def sim(self) -> RoverSim:
        return self.world.sim

    @property
    def terrain(self):  # noqa: ANN201
        return self.world.terrain

    @property
    def renderer(self):  # noqa: ANN201
        return self.world.renderer

    @property
    def vo_steps(self) -> list[VoStepRecord]:
        return self.evaluator.vo_steps

    def trajectories(self) -> dict[str, Trajectory]:
        return self.evaluator.trajectories()

    def close(self) -> None:
        self.world.close()

    # ------------------------------------------------------------------ the loop
    def run(self) -> Metrics:
        t0 = time.perf_counter()
        try:
            self.log_static()
            self.tick(self.sim)
            if self.onboard.vo is not None:
                self.vo_update()  # the first pair initialises VO
            skipping = False  # the sol's budget is spent: its remaining commands are skipped up to the next sleep
            for i, cmd in enumerate(self.sc.commands):
                if skipping and not isinstance(cmd, SleepCmd):
                    self.event(f"command {i}: {cmd.type} skipped (the sol's budget is spent)")
                    continue
                skipping = False
                self.event(f"command {i}: {cmd.type}")
                try:
                    self.run_command(cmd)
                except BudgetSpent as b:
                    if not any(isinstance(c, SleepCmd) for c in self.sc.commands[i + 1 :]):
                        raise  # the last sol: the drive is over
                    self.event(f"sol {self.sol.current.number}: {b}")  # type: ignore[union-attr]
                    self.sim.hold()  # parked where the budget ran out, until the sleep
                    skipping = True
        except BudgetSpent as b:  # the day's drive is over: an outcome, not a halt
            self.event(f"sol: {b}")
        except Halt as h:
            self.halted = h
            self.event(f"HALT {h.kind}: {h.detail}", "WARN")
        except (PhysicsDiverged, PluginError) as e:
            self.error = str(e)
            self.event(str(e), "ERROR")
        except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM as errors.Terminated
            self.interrupted = e
            self.error = interrupts.describe(e)
            self.event(self.error, "ERROR")
        finally:
            self.world.sensors.detach()
            if self.rut_log is not None:
                self.rut_log.flush(self.sim.time_s, self.step)
        return self.metrics(time.perf_counter() - t0)

    def run_command(self, cmd) -> None:  # noqa: ANN001
        if self.sol is not None:
            self.sol.mode = "autonav" if isinstance(cmd, AutonavCmd) else "blind"
        if isinstance(cmd, DriveCmd):
            self.drive_with_vo(Straight(cmd.distance_m), abs(cmd.distance_m))
        elif isinstance(cmd, ArcCmd):
            self.drive_with_vo(Arc(cmd.radius_m, cmd.distance_m), abs(cmd.distance_m))
        elif isinstance(cmd, TurnCmd):
            self.execute(TurnInPlace(math.radians(cmd.angle_deg)))
            self.vo_update()
        elif isinstance(cmd, MastCmd):
            self.point_mast(cmd.pan_deg, cmd.tilt_deg)
            self.world.calibrate(self.sc.nav.camera)
            if self.onboard.vo is not None:
                self.reset_vo()
                self.vo_update()
        elif isinstance(cmd, GotoCmd):
            self.goto(cmd)
            self.evaluator.site(self.world.truth_pose(), self.onboard.dead_reckoning.pose, self.onboard.pose)
        elif isinstance(cmd, AutonavCmd):
            from rover_sim.apps.autonav import run_autonav  # autonav drives this class: imported at use

            try:
                run_autonav(self, cmd)
            finally:  # also when a sol's budget cut it short
                stats = self.autonav_stats
                self._autonav_runs.append(stats)
                if self.sol is not None and stats is not None:
                    self.sol.note_autonav(stats.cycles, stats.backtracks, stats.outcome)
        elif isinstance(cmd, SleepCmd):
            self.sleep(cmd)

    # ------------------------------------------------------------------ commands
    def execute(self, prim: Primitive) -> None:
        """Drive one primitive at the scenario's speed; :meth:`tick` runs at 8 Hz meanwhile."""
        execute(self.sim, prim, self.sc.nav.speed_m_s, on_tick=self.tick, geom=self.onboard.geometry)

    def stand(self, duration_s: float, tick_s: float = 0.125) -> None:
        """Stand still (wheels idle) for ``duration_s``; the onboard estimators keep running."""
        for _ in range(int(round(duration_s / tick_s))):
            self.sim.step(None, int(round(tick_s / self.sim.timestep_s)))
            self.tick(self.sim)

    def point_mast(self, pan_deg: float, elevation_deg: float, settle_s: float = MAST_SETTLE_S) -> None:
        """Command the mast (pan left positive, elevation up positive) and wait for the servos."""
        self.world.point_mast(pan_deg, elevation_deg)
        self.sim.step(None, int(round(settle_s / self.sim.timestep_s)))
        self.tick(self.sim)

    def drive_with_vo(self, prim: Straight | Arc, length_m: float) -> None:
        """Blind drive; with VO on it is cut into ``vo_step_m`` pieces with a stereo pair after each."""
        if self.onboard.vo is None:
            self.execute(prim)
            return
        n = max(1, math.ceil(length_m / self.sc.nav.vo_step_m - 1e-9))
        slope_deg = self.sc.sol.vo_min_slope_deg if self.sc.sol is not None else None
        for _ in range(n):
            piece = (
                Straight(prim.distance_m / n) if isinstance(prim, Straight) else Arc(prim.radius_m, prim.distance_m / n)
            )
            on_slope = slope_deg is None or _tilt_deg(self.onboard.pose.R_world_rover) > slope_deg
            if self.sol is not None:
                self.sol.mode = "blind_vo" if on_slope else "blind"
            self.execute(piece)
            if on_slope:
                self.vo_update()
            else:  # flat ground: no VO pair (MER); the next VO step on a slope starts afresh
                self.reset_vo()

    def sleep(self, cmd: SleepCmd) -> None:
        """End of sol: park with the wheels held and sleep to the next sol's wake-up time.

        No physics is stepped overnight: a parked MER does not move (its wheel drives hold), and the wheel-soil law
        holds a parked rover on the plains, so the rover stays where it stopped; simulation time does not advance.
        The mission clock advances to the wake-up time (charged as ``sleeping``, not drive time: the next sol's
        budgets start at the wake-up) and a moving sun (``sun.local_solar_time_h``) is moved to it. Onboard
        estimates are kept: dead reckoning keeps its pose (nothing moved, and no 8 Hz tick is missed since
        simulation time stands still); VO forgets its last pair (next morning's pair, under another sun, starts a
        new VO sequence, as each sol's drive did); autonav starts each command with an empty map anyway.
        """
        assert self.sol is not None  # the scenario refuses a sleep without a [sol] table
        self.sim.hold()
        self.world.sync_clock()
        ended = self.sol.current.number
        slept_s = self.sol.sleep(self.sc.wake_local_solar_time_h(cmd))
        if self.sc.sun.local_solar_time_h is not None:
            self.world.move_sun()
        if self.onboard.vo is not None:
            self.reset_vo()
        lst = self.world.clock.local_solar_time_h  # type: ignore[union-attr]
        self.event(f"sol {ended} over: slept {slept_s:.0f} s; sol {ended + 1} wakes at {lst:.2f} h local solar time")

    def goto(self, cmd: GotoCmd) -> None:
        """Drive to (x, y) on the onboard pose: turn toward the goal, drive a VO step, repeat (Sol 304 style)."""
        budget = cmd.max_distance_m
        goal = np.array([cmd.x_m, cmd.y_m])
        while budget > 0:
            pose = self.onboard.pose
            delta = goal - pose.position_xyz_m[:2]
            dist = float(np.linalg.norm(delta))
            if dist <= cmd.tolerance_m:
                self.event(f"goto ({cmd.x_m}, {cmd.y_m}) reached on the onboard pose")
                return
            err = _wrap(math.atan2(delta[1], delta[0]) - heading_rad(pose.R_world_rover))
            if abs(err) > GOTO_HEADING_TOLERANCE_RAD:
                self.execute(TurnInPlace(err))
                if self.onboard.vo is not None:
                    self.vo_update()
            step = min(self.sc.nav.vo_step_m, dist)
            self.execute(Straight(step))
            budget -= step
            if self.onboard.vo is not None:
                self.vo_update()
        self.event(f"goto ({cmd.x_m}, {cmd.y_m}): travel budget used up", "WARN")

    # ------------------------------------------------------------------ per tick
    def tick(self, sim: RoverSim | None = None) -> str | None:
        """Sensors -> onboard dead reckoning -> evaluator -> keep-out check -> recording (8 Hz)."""
        sim = self.sim
        obs = self.world.observation()
        self.onboard.observe(obs)
        keep = self.step % self.pose_stride == 0
        truth = self.record_poses() if keep else self.world.truth_pose()
        for listener in self.tick_listeners:
            listener(obs, truth)
        tall = sim.rock_contacts(TALL_ROCK_M)
        self.evaluator.count_contacts(bool(sim.body_contacts()), bool(tall))
        if tall and self.evaluator.tall_rock_contact_ticks == 1:
            self.event(f"contact with a rock taller than {TALL_ROCK_M} m: {tall[0]}", "WARN")
        self.step += 1
        t = sim.time_s
        if keep:
            self.rec.log_rover_pose(t, self.step, truth.position_xyz_m, truth.quat_wxyz)
        if self.step % (4 * self.pose_stride) == 0:
            self.log_tracks(t)
        if sim.terrain_version != self._terrain_version:
            self.log_terrain_tiles()
        if self.rut_log is not None:
            self.rut_log.update(t, self.step)
        if self.progress is not None:
            self.progress(t, "")
        self.check_keep_out()
        if self.sol is not None:
            self.world.sync_clock()
            self.sol.on_tick(t, truth.position_xyz_m, self.onboard.dead_reckoning.distance_m)
        if sim.soil_model != "bekker":  # the Wong-Reece law: left_terrain / slid_down_slope halts
            issue = sim.safety_issue()
            if issue is not None:
                raise Halt(*issue)
        return None

    def record_poses(self) -> Pose:
        """Hand the evaluator the truth beside the dead-reckoned and onboard poses; returns the truth."""
        truth = self.world.truth_pose()
        ob = self.onboard
        self.evaluator.record(truth, ob.dead_reckoning.pose, ob.pose, ob.dead_reckoning.distance_m)
        return truth

    def check_keep_out(self) -> None:
        zones = [(z.name, z.x_m, z.y_m, z.radius_m) for z in self.sc.keep_out]
        hit = self.onboard.keep_out_violation(zones)
        if hit is None:
            return
        name, d = hit
        z = next(z for z in self.sc.keep_out if z.name == name)
        q = self.onboard.dead_reckoning.pose.position_xyz_m
        t = self.sim.position_m()
        info = self.evaluator.keep_out(
            name, d, math.hypot(q[0] - z.x_m, q[1] - z.y_m), math.hypot(t[0] - z.x_m, t[1] - z.y_m)
        )
        raise Halt(
            "keep_out",
            f"onboard pose {d:.2f} m from {z.name} (limit {z.radius_m} m); dead "
            f"reckoning thinks {info['dead_reckoning_distance_m']:.2f} m",
        )

    # ------------------------------------------------------------------ VO
    def vo_update(self) -> VoStep | None:
        """Image the VO pair, run one onboard VO step, score it, log it; halts on the slip limit."""
        if self.onboard.vo is None:
            return None
        camera = self.sc.nav.camera
        no_texture = seek_texture(self) if self.sc.nav.vo.seek_texture else False
        frame = self.world.render(camera)
        textured = self.world.textured_view_fraction(camera)  # truth: for the evaluator only
        obs = self.world.observation_with([], [], {camera: frame})
        self.notify_images(obs)
        out = self.onboard.vo_step(obs, camera)
        self.world.charge("computing", VO_STEP_COMPUTE_S)
        res = out.result
        record = self.evaluator.vo_step(
            self.world.truth_pose(), res.status, res.motion_rover, out.commanded_m, int(res.n_inliers), out.ms,
            reason=str(getattr(res, "reason", "")), no_texture=no_texture, covariance=getattr(res, "covariance", None),
            textured_frac=textured,
        )  # fmt: skip
        t = self.sim.time_s
        if record is not None:
            self.rec.log_scalars(
                t,
                self.step,
                {
                    "slip_pct/true": 100.0 * record.true_slip,
                    "slip_pct/vo": 100.0 * record.vo_slip,
                    "vo_inliers": float(res.n_inliers),
                },
            )
            if res.status != "ok":
                self.event(f"VO {res.status}: {res.reason}", "WARN")
            elif record.false_positive:
                self.event(f"VO accepted an update {100 * record.error_m:.1f} cm off (false positive)", "ERROR")
        if res.status == "ok":
            self.record_poses()  # the corrected pose at the frame time
        for listener in self.vo_listeners:
            listener(out, obs.pair(camera).rig.left.T_rover_cam)
        self.log_frame(obs, camera, res)
        if getattr(res, "failure_limit_reached", False):  # MER flight software: too many VO failures stop the drive
            raise Halt("vo_failures", f"VO failed to converge on too many consecutive steps (last: {res.status})")
        limit = self.sc.nav.slip_limit
        if limit is not None and record is not None and res.status == "ok" and abs(out.commanded_m) > 0.05:
            if out.vo_slip > limit:
                raise Halt("slip_limit", f"VO measured {100 * out.vo_slip:.0f} % slip (limit {100 * limit:.0f} %)")
        return out

    def reset_vo(self) -> None:
        """VO forgets its previous pair (the mast moved, or a new sol starts), and so does every listener's."""
        self.onboard.reset_vo()
        for listener in self.vo_reset_listeners:
            listener()

    def notify_images(self, obs: Observation) -> None:
        """Hand a freshly imaged observation (and the truth at that instant) to the image listeners."""
        if self.image_listeners:
            truth = self.world.truth_pose()
            for listener in self.image_listeners:
                listener(obs, truth)

    # ------------------------------------------------------------------ logging
    def event(self, text: str, level: str = "INFO") -> None:
        self.events.append(f"[{self.sim.time_s:8.2f}s] {level}: {text}")
        self.rec.log_event(self.sim.time_s, self.step, text, level)

    # ------------------------------------------------------------------ evaluation
    def metrics(self, wall_s: float) -> Metrics:
        self._wall_s = wall_s
        if not self.evaluator.truth:  # stopped before the first tick: the start pose is the whole trajectory
            self.record_poses()
        extra: dict = {}
        if self.evaluator.keep_out_info:
            extra["keep_out"] = self.evaluator.keep_out_info
        clock = self.world.clock_summary()
        if clock is not None:  # only with a moving sun (sun.local_solar_time_h): other metrics stay as they were
            extra["clock"] = clock
        timing: dict = {}
        runs = self._autonav_runs if len(self._autonav_runs) > 1 else [self.autonav_stats]
        if runs[-1] is not None:  # several autonav commands (several sols): cycles summed, the last outcome
            extra["autonav"] = {
                "cycles": sum(r.cycles for r in runs),
                "backtracks": sum(r.backtracks for r in runs),
                "outcome": runs[-1].outcome,
            }
            cycle_ms = [ms for r in runs for ms in r.cycle_ms]
            if cycle_ms:
                timing["autonav_cycle_ms_median"] = round(float(np.median(cycle_ms)), 1)
        timing["realtime_factor"] = round(self.sim.time_s / max(wall_s, 1e-9), 1)
        if self.sol is not None:
            extra["sol"] = self.sol.summary()
        if self.sim.soil_model != "bekker" or self.sc.passing.judges_wheels():  # the default law's metrics unchanged
            c = self.sim.wheel_centres_m()
            ground = self.sim.terrain.height_at(c[:, 0], c[:, 1])  # undisturbed (the deformed surface is separate)
            extra["wheels"] = self.evaluator.final_wheels(c, ground, WHEEL_RADIUS_M, self.sim.law.state.sinkage_m)
        if self.sim.streamer is not None:
            st = self.sim.streamer
            extra["streamed_terrain"] = {"recentres": st.recentres, "tiles_built": st.site.tiles_built,
                                         "rocks_dropped": st.rocks_dropped}  # fmt: skip
        m = self.evaluator.metrics(
            wall_s=wall_s,
            sim_s=self.sim.time_s,
            halted=self.halted.kind if self.halted else None,
            extra=extra,
            timing=timing,
        )
        m.pointing_changes = self.pointing_changes
        m.passed, m.reason = acceptance.judge(
            m,
            self.sc.passing,
            error=self.error,
            keep_out_info=self.evaluator.keep_out_info,
            keep_out=list(self.sc.keep_out),
        )
        return m

    def _last_goal(self) -> np.ndarray | None:
        for c in reversed(self.sc.commands):
            if isinstance(c, GotoCmd | AutonavCmd):
                return np.array([c.x_m, c.y_m])
        return None
