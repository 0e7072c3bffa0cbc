"""The closed-loop mission runner: scenario -> world -> commands -> nav stack in the loop -> metrics and outputs.

It owns the simulation, the sensors, the renderer, the onboard navigation (dead reckoning, visual odometry,
GESTALT) and the recorder; the algorithms in ``nav`` know none of them (kiss-icp ``pipeline.py`` style).

Information flow (the honesty rule): the onboard estimators see only rendered images, camera models, IMU and
encoder samples and the operator-given start pose (as on Mars, where the start of a drive came from the previous
localisation and sun finding). Ground truth goes only to the recorder and to the evaluation below.

Per 8 Hz tick: IMU samples since the last tick + an encoder sample -> two dead reckoners (one pure wheel/IMU for
comparison, one onboard that VO corrects) -> keep-out check on the onboard pose -> logging.
VO: the rover stops every ``nav.vo_step_m`` of commanded travel, takes a stereo pair and runs one VO step;
an accepted motion replaces the dead-reckoned increment since the previous pair (MER practice).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from nav.camera import transform_points
from nav.dead_reckoning import DeadReckoner
from nav.geometry import R_to_rpy, se3_inv
from nav.stereo import StereoParams, range_image
from nav.trajectory import Pose, Trajectory, relative_errors, write_tum
from nav.types import RoverGeometry
from nav.vo import VisualOdometry
from rover_sim.errors import PhysicsDiverged
from rover_sim.io.recording import NullRecorder, Recorder
from rover_sim.mission.scenario import ArcCmd, AutonavCmd, DriveCmd, GotoCmd, MastCmd, Scenario, TurnCmd
from rover_sim.render.renderer import ImageNoise, RenderConfig, StereoRenderer, terrain_texture
from rover_sim.sim.drive import Arc, Primitive, Straight, TurnInPlace, execute
from rover_sim.sim.physics import RoverSim
from rover_sim.sim.sensors import SensorSuite
from rover_sim.sim.world import Sun
from terrains import synthesize

TALL_ROCK_M = 0.25  # GESTALT must avoid touching rocks at least this tall (wheel or body)
FALSE_POSITIVE_M = 0.05  # an accepted VO update whose translation is off by more than this is a false positive
GOTO_HEADING_TOLERANCE_RAD = math.radians(5.0)
MAX_TEXTURE_SIDE_PX = 8192  # ground texture memory stays under ~200 MB


class Halt(Exception):
    """The drive sequence stops (keep-out, slip limit): expected, recorded as the mission outcome."""

    def __init__(self, kind: str, detail: str) -> None:
        self.kind, self.detail = kind, detail
        super().__init__(f"{kind}: {detail}")


@dataclass
class VoStepRecord:
    t_s: float
    status: str
    commanded_m: float  # wheel-odometry distance since the previous pair
    vo_made_good_m: float  # VO-measured progress along the previous heading (NaN if no update)
    true_made_good_m: float
    vo_slip: float
    true_slip: float
    error_m: float  # |VO translation - true translation| (NaN if no update)
    n_inliers: int
    ms: float


@dataclass
class Metrics:
    """metrics.json (keys of the issue first, then extras)."""

    scenario: str
    seed: int
    distance_m: float
    dr_error_pct: float
    vo_error_pct: float | None
    vo_convergence_pct: float | None
    max_slip_pct: float
    mean_slip_pct: float
    passed: bool
    reason: str
    wall_s: float
    halted: str | None = None
    dr_error_m: float = math.nan
    vo_error_m: float | None = None
    false_positives: int = 0
    vo_steps: int = 0
    vo_accepted: int = 0
    max_vo_slip_pct: float | None = None
    body_collisions: int = 0  # ticks with the body (not a wheel) touching terrain or a rock
    tall_rock_contacts: int = 0  # ticks with any rover geom touching a rock >= TALL_ROCK_M tall
    goal_distance_m: float | None = None
    sim_s: float = 0.0
    extra: dict = field(default_factory=dict)
    # wall-clock measurements: not deterministic, so written to timing.json rather than metrics.json
    timing: dict = field(default_factory=dict)

    @property
    def vo_step_ms_median(self) -> float | None:
        return self.timing.get("vo_step_ms_median")

    def deterministic_dict(self) -> dict:
        d = asdict(self)
        d.pop("timing")
        return d


def _heading(q_wxyz: np.ndarray) -> float:
    from nav.geometry import quat_wxyz_to_R

    R = quat_wxyz_to_R(q_wxyz)
    return float(math.atan2(R[1, 0], R[0, 0]))


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class Mission:
    """One scenario run. ``run()`` returns :class:`Metrics`; outputs go to ``out_dir`` when given."""

    def __init__(
        self,
        scenario: Scenario,
        recorder: Recorder | None = None,
        progress: Callable[[float, str], None] | None = None,
    ) -> None:
        self.sc = scenario
        self.rec: Recorder = recorder or NullRecorder()
        self.progress = progress
        self.geom = RoverGeometry()
        self.terrain = synthesize(scenario.terrain, scenario.seed)
        ap = scenario.appearance
        texture = terrain_texture(
            self.terrain, self._texture_px_per_m(), scenario.seed, fine_soil=ap.fine_soil, contrast=ap.contrast
        )
        self.sim = RoverSim(
            self.terrain,
            Sun(scenario.sun.azimuth_deg, scenario.sun.elevation_deg, scenario.sun.shadows),
            texture_rgb=texture,
            timestep_s=scenario.physics.timestep_s,
        )
        self.sim.lock_wheels(list(scenario.faults.locked_wheels))
        st = scenario.start
        self.sim.place(st.x_m, st.y_m, math.radians(st.yaw_deg))
        self._point_mast(scenario.nav.mast_pan_deg, scenario.nav.mast_tilt_deg)
        self.sim.step_for(1.0)
        self.sensors = SensorSuite(self.sim, seed=scenario.seed)  # samples the IMU inside the physics loop
        self._imu_pending: list = []
        noise = ImageNoise(seed=scenario.seed) if scenario.nav.image_noise else None
        self.renderer = StereoRenderer(
            self.sim, RenderConfig(resolution_px=scenario.nav.resolution_px, noise=noise, shadows=scenario.sun.shadows)
        )
        # The camera model flight software uses: calibrated at the commanded mast pointing, fixed until repointed
        self._nav_rig = self.renderer.rig(scenario.nav.camera)
        self._stereo_params = StereoParams(num_disparities=64)
        # The operator-given start pose (from the previous localisation); estimators never see truth after this.
        start = Pose(self.sim.time_s, self.sim.position_m(), self.sim.quat_wxyz())
        self.dr = DeadReckoner(self.geom, start)
        self.onboard = DeadReckoner(self.geom, start)
        self.vo = VisualOdometry() if scenario.nav.vo else None
        self.truth: list[Pose] = []
        self.dr_poses: list[Pose] = []
        self.onboard_poses: list[Pose] = []
        self.vo_steps: list[VoStepRecord] = []
        self.events: list[str] = []
        self.halted: Halt | None = None
        self.error: str | None = None
        self.step = 0
        self.keep_out_info: dict | None = None
        self.autonav_stats = None  # set by rover_sim.mission.autonav when the scenario uses autonav
        self.body_collision_ticks = 0
        self.tall_rock_contact_ticks = 0
        self._last_frame_truth: np.ndarray | None = None
        self._last_frame_dr_distance = 0.0
        self._frame_idx = 0

    # ------------------------------------------------------------------ setup helpers
    def _texture_px_per_m(self) -> float:
        side = 2.0 * max(self.terrain.half_x_m, self.terrain.half_y_m)
        return float(min(self.sc.appearance.texture_px_per_m, MAX_TEXTURE_SIDE_PX / side))

    def _point_mast(self, pan_deg: float, elevation_deg: float) -> None:
        """Pan (left positive) and elevation (up positive); the tilt joint turns about +y, so it is -elevation."""
        self.sim.set_mast(math.radians(pan_deg), -math.radians(elevation_deg))

    # ------------------------------------------------------------------ the loop
    def run(self) -> Metrics:
        t0 = time.perf_counter()
        self._log_static()
        self._tick(self.sim)
        try:
            if self.vo is not None:
                self._vo_update()  # the first pair initialises VO
            for i, cmd in enumerate(self.sc.commands):
                self._event(f"command {i}: {cmd.type}")
                self._run_command(cmd)
        except Halt as h:
            self.halted = h
            self._event(f"HALT {h.kind}: {h.detail}", "WARN")
        except PhysicsDiverged as e:
            self.error = str(e)
            self._event(str(e), "ERROR")
        except KeyboardInterrupt:
            self.error = "interrupted (Ctrl-C)"
            self._event(self.error, "ERROR")
        finally:
            self.sensors.detach()
        return self._metrics(time.perf_counter() - t0)

    def _run_command(self, cmd) -> None:
        if isinstance(cmd, DriveCmd):
            self._drive_with_vo(Straight(cmd.distance_m), abs(cmd.distance_m))
        elif isinstance(cmd, ArcCmd):
            self._drive_with_vo(Arc(cmd.radius_m, cmd.distance_m), abs(cmd.distance_m))
        elif isinstance(cmd, TurnCmd):
            self._primitive(TurnInPlace(math.radians(cmd.angle_deg)))
            self._vo_update()
        elif isinstance(cmd, MastCmd):
            self._point_mast(cmd.pan_deg, cmd.tilt_deg)
            self.sim.step(None, int(round(2.0 / self.sim.timestep_s)))
            self._tick(self.sim)
            self._nav_rig = self.renderer.rig(self.sc.nav.camera)
            if self.vo is not None:
                self.vo.reset()
                self._vo_update()
        elif isinstance(cmd, GotoCmd):
            self._goto(cmd)
        elif isinstance(cmd, AutonavCmd):
            self._autonav(cmd)

    # ------------------------------------------------------------------ commands
    def _primitive(self, prim: Primitive) -> None:
        execute(self.sim, prim, self.sc.nav.speed_m_s, on_tick=self._tick, geom=self.geom)

    def _drive_with_vo(self, prim: Straight | Arc, length_m: float) -> None:
        """Blind drive; with VO on it is cut into ``vo_step_m`` pieces with a stereo pair after each."""
        if self.vo is None:
            self._primitive(prim)
            return
        n = max(1, math.ceil(length_m / self.sc.nav.vo_step_m - 1e-9))
        for _ in range(n):
            piece = (
                Straight(prim.distance_m / n) if isinstance(prim, Straight) else Arc(prim.radius_m, prim.distance_m / n)
            )
            self._primitive(piece)
            self._vo_update()

    def _goto(self, cmd: GotoCmd) -> None:
        """Drive to (x, y) on the onboard pose: turn toward the goal, drive a VO step, repeat (Sol 304 style)."""
        budget = cmd.max_distance_m
        goal = np.array([cmd.x_m, cmd.y_m])
        while budget > 0:
            pose = self.onboard.pose
            delta = goal - pose.position_xyz_m[:2]
            dist = float(np.linalg.norm(delta))
            if dist <= cmd.tolerance_m:
                self._event(f"goto ({cmd.x_m}, {cmd.y_m}) reached on the onboard pose")
                return
            err = _wrap(math.atan2(delta[1], delta[0]) - _heading(pose.quat_wxyz))
            if abs(err) > GOTO_HEADING_TOLERANCE_RAD:
                self._primitive(TurnInPlace(err))
                if self.vo is not None:
                    self._vo_update()
            step = min(self.sc.nav.vo_step_m, dist)
            self._primitive(Straight(step))
            budget -= step
            if self.vo is not None:
                self._vo_update()
        self._event(f"goto ({cmd.x_m}, {cmd.y_m}): travel budget used up", "WARN")

    def _autonav(self, cmd: AutonavCmd) -> None:
        from rover_sim.mission.autonav import run_autonav

        run_autonav(self, cmd)

    # ------------------------------------------------------------------ per tick
    def _tick(self, sim: RoverSim) -> str | None:
        imu, encoders = self.sensors.poll()
        self._imu_pending.extend(imu)
        if encoders:  # 8 Hz pose update: the IMU samples since the last encoder reading plus the new reading
            self.dr.update(self._imu_pending, encoders[-1])
            self.onboard.update(self._imu_pending, encoders[-1])
            self._imu_pending = []
        t = sim.time_s
        truth = self._record_poses()
        if sim.body_contacts():
            self.body_collision_ticks += 1
        tall = sim.rock_contacts(TALL_ROCK_M)
        if tall:
            self.tall_rock_contact_ticks += 1
            if self.tall_rock_contact_ticks == 1:
                self._event(f"contact with a rock taller than {TALL_ROCK_M} m: {tall[0]}", "WARN")
        self.step += 1
        self.rec.log_rover_pose(t, self.step, truth.position_xyz_m, truth.quat_wxyz)
        if self.step % 4 == 0:
            self._log_tracks(t)
        if self.progress is not None:
            self.progress(t, "")
        return self._keep_out_check()

    def _record_poses(self) -> Pose:
        """Append truth, dead-reckoned and onboard poses at the current time; returns the truth."""
        sim = self.sim
        truth = Pose(sim.time_s, sim.position_m(), sim.quat_wxyz())
        self.truth.append(truth)
        self.dr_poses.append(self.dr.pose)
        self.onboard_poses.append(self.onboard.pose)
        return truth

    def _keep_out_check(self) -> str | None:
        p = self.onboard.pose.position_xyz_m
        for z in self.sc.keep_out:
            d = math.hypot(p[0] - z.x_m, p[1] - z.y_m)
            if d < z.radius_m:
                q = self.dr.pose.position_xyz_m
                t = self.sim.position_m()
                self.keep_out_info = {
                    "zone": z.name,
                    "onboard_distance_m": round(d, 3),
                    "dead_reckoning_distance_m": round(math.hypot(q[0] - z.x_m, q[1] - z.y_m), 3),
                    "true_distance_m": round(math.hypot(t[0] - z.x_m, t[1] - z.y_m), 3),
                }
                raise Halt(
                    "keep_out",
                    f"onboard pose {d:.2f} m from {z.name} (limit {z.radius_m} m); dead "
                    f"reckoning thinks {self.keep_out_info['dead_reckoning_distance_m']:.2f} m",
                )
        return None

    # ------------------------------------------------------------------ VO
    def _vo_update(self) -> None:
        if self.vo is None:
            return
        sim = self.sim
        frame = self.renderer.render_pair(self.sc.nav.camera)
        pred = self.onboard.predicted_motion_rover()
        commanded = self.onboard.distance_m - self._last_frame_dr_distance
        prev_R = self.onboard.vo_frame_pose.R_world_rover
        t0 = time.perf_counter()
        res = self.vo.step(frame.left, frame.right, self._nav_rig, pred, R_world_rover=prev_R)
        ms = (time.perf_counter() - t0) * 1e3
        T_truth = Pose(sim.time_s, sim.position_m(), sim.quat_wxyz()).as_matrix()
        status = res.status
        if self._last_frame_truth is not None and status != "first_frame":
            true_motion = se3_inv(self._last_frame_truth) @ T_truth
            true_good = float(true_motion[0, 3])
            vo_good, err = math.nan, math.nan
            if res.ok:
                vo_good = float(res.motion_rover[0, 3])
                err = float(np.linalg.norm(res.motion_rover[:3, 3] - true_motion[:3, 3]))
            rec = VoStepRecord(
                sim.time_s,
                status,
                commanded,
                vo_good,
                true_good,
                1.0 - vo_good / commanded if abs(commanded) > 1e-3 and res.ok else math.nan,
                1.0 - true_good / commanded if abs(commanded) > 1e-3 else math.nan,
                err,
                res.n_inliers,
                ms,
            )
            self.vo_steps.append(rec)
            self.rec.log_scalars(
                sim.time_s,
                self.step,
                {"slip/true": rec.true_slip, "slip/vo": rec.vo_slip, "vo_inliers": float(res.n_inliers)},
            )
            if not res.ok:
                self._event(f"VO {status}: {res.reason}", "WARN")
            elif err > FALSE_POSITIVE_M:
                self._event(f"VO accepted an update {100 * err:.1f} cm off (false positive)", "ERROR")
        if res.ok:
            self.onboard.apply_vo_correction(res.motion_rover)
            self._record_poses()  # the corrected pose at the frame time
        else:
            self.onboard.mark_vo_frame()
        self._last_frame_truth = T_truth
        self._last_frame_dr_distance = self.onboard.distance_m
        self._frame_idx += 1
        self._log_frame(frame, res)
        limit = self.sc.nav.slip_limit
        if limit is not None and self.vo_steps and res.ok and abs(commanded) > 0.05:
            s = self.vo_steps[-1].vo_slip
            if s > limit:
                raise Halt("slip_limit", f"VO measured {100 * s:.0f} % slip (limit {100 * limit:.0f} %)")

    # ------------------------------------------------------------------ logging
    def _event(self, text: str, level: str = "INFO") -> None:
        self.events.append(f"[{self.sim.time_s:8.2f}s] {level}: {text}")
        self.rec.log_event(self.sim.time_s, self.step, text, level)

    def _log_static(self) -> None:
        self.rec.log_terrain(self.terrain)
        for z in self.sc.keep_out:
            self.rec.log_keep_out(z.name, z.x_m, z.y_m, z.radius_m, float(self.terrain.height_at(z.x_m, z.y_m)))
        self.rec.log_camera(self.sc.nav.camera, self.renderer.rig(self.sc.nav.camera), self.sim.time_s)

    def _log_tracks(self, t: float) -> None:
        for name, poses in (("truth", self.truth), ("dead_reckoning", self.dr_poses)):
            self.rec.log_trajectory(name, t, self.step, np.array([p.position_xyz_m for p in poses]))
        if self.vo is not None:
            self.rec.log_trajectory("vo", t, self.step, np.array([p.position_xyz_m for p in self.onboard_poses]))
        truth = self.truth[-1]
        rpy = R_to_rpy(truth.R_world_rover)
        gt = self.sim.ground_truth()
        self.rec.log_scalars(
            t,
            self.step,
            {
                "tilt_deg": gt.tilt_deg,
                "roll_deg": math.degrees(rpy[0]),
                "pitch_deg": math.degrees(rpy[1]),
                "position_error_m/dead_reckoning": float(
                    np.linalg.norm(self.dr_poses[-1].position_xyz_m - truth.position_xyz_m)
                ),
                "position_error_m/vo": float(
                    np.linalg.norm(self.onboard_poses[-1].position_xyz_m - truth.position_xyz_m)
                ),
                "wheel_slip_mean": float(np.nanmean(gt.wheel_slip)) if np.isfinite(gt.wheel_slip).any() else math.nan,
                "sinkage_mean_m": float(np.mean(gt.wheel_sinkage_m)),
            },
        )

    def _log_frame(self, frame, res) -> None:
        name = self.sc.nav.camera
        t = self.sim.time_s
        self.rec.log_camera(name, frame.rig, t)
        disparity = None
        if self.rec.wants_images():
            # dense SAD stereo of the VO pair, for the recording only (placed with the onboard pose)
            ri = range_image(frame.left, frame.right, frame.rig, self._stereo_params)
            disparity = ri.disparity_px
            pts = transform_points(self.onboard.pose.as_matrix(), ri.points_rover_m())
            self.rec.log_points(name, t, self.step, pts[np.linalg.norm(pts[:, :2] - pts[:, :2].mean(0), axis=1) < 15])
        self.rec.log_stereo_images(name, t, self.step, frame.left, frame.right, disparity)
        if res.tracks is not None and len(res.tracks):
            inl = res.inliers if res.inliers is not None else np.ones(len(res.tracks), bool)
            self.rec.log_vo_features(name, t, self.step, res.tracks.uv_prev_left, res.tracks.uv_cur_left, inl)

    # ------------------------------------------------------------------ evaluation
    def trajectories(self) -> dict[str, Trajectory]:
        out = {"truth": Trajectory.from_poses(self.truth), "dead_reckoning": Trajectory.from_poses(self.dr_poses)}
        if self.vo is not None:
            out["vo"] = Trajectory.from_poses(self.onboard_poses)
        return out

    def _metrics(self, wall_s: float) -> Metrics:
        self._wall_s = wall_s
        tr = self.trajectories()
        truth = tr["truth"]
        dist = max(truth.path_length_m(), 1e-9)
        end = truth.positions_xyz[-1]
        dr_err = float(np.linalg.norm(tr["dead_reckoning"].positions_xyz[-1] - end))
        vo_err = float(np.linalg.norm(tr["vo"].positions_xyz[-1] - end)) if "vo" in tr else None
        steps = [s for s in self.vo_steps]
        judged = [s for s in steps if s.status not in ("first_frame", "reinit")]
        accepted = [s for s in judged if s.status == "ok"]
        conv = 100.0 * len(accepted) / len(judged) if judged else None
        fps = sum(1 for s in accepted if s.error_m > FALSE_POSITIVE_M)
        true_slips = np.array([s.true_slip for s in steps if abs(s.commanded_m) > 0.05], dtype=float)
        true_slips = true_slips[np.isfinite(true_slips)]
        vo_slips = np.array([s.vo_slip for s in accepted if abs(s.commanded_m) > 0.05], dtype=float)
        vo_slips = vo_slips[np.isfinite(vo_slips)]
        if len(true_slips) == 0:  # no VO: per-tick slip from the drive as a whole
            cmd = self.dr.distance_m
            true_slips = np.array([1.0 - float(np.dot(end - truth.positions_xyz[0], truth.matrices()[0][:3, 0])) / cmd])
            if abs(cmd) < 0.05:
                true_slips = np.array([0.0])
        ms = [s.ms for s in steps]
        goal = self._last_goal()
        m = Metrics(
            scenario=self.sc.name,
            seed=self.sc.seed,
            distance_m=round(dist, 4),
            dr_error_pct=round(100 * dr_err / dist, 3),
            vo_error_pct=round(100 * vo_err / dist, 3) if vo_err is not None else None,
            vo_convergence_pct=round(conv, 2) if conv is not None else None,
            max_slip_pct=round(100 * float(np.max(true_slips)), 2),
            mean_slip_pct=round(100 * float(np.mean(true_slips)), 2),
            passed=False,
            reason="",
            wall_s=round(wall_s, 2),
            halted=self.halted.kind if self.halted else None,
            dr_error_m=round(dr_err, 4),
            vo_error_m=round(vo_err, 4) if vo_err is not None else None,
            false_positives=fps,
            vo_steps=len(judged),
            vo_accepted=len(accepted),
            max_vo_slip_pct=round(100 * float(np.max(vo_slips)), 2) if len(vo_slips) else None,
            body_collisions=self.body_collision_ticks,
            tall_rock_contacts=self.tall_rock_contact_ticks,
            goal_distance_m=round(float(np.linalg.norm(end[:2] - goal)), 3) if goal is not None else None,
            sim_s=round(self.sim.time_s, 2),
            extra=self._extra(),
            timing=self._timing(ms),
        )
        m.passed, m.reason = self._judge(m)
        return m

    def _extra(self) -> dict:
        out: dict = {"kitti_translation_error_pct": self._kitti()}
        if self.keep_out_info:
            out["keep_out"] = self.keep_out_info
        if self.autonav_stats is not None:
            out["autonav"] = {
                "cycles": self.autonav_stats.cycles,
                "backtracks": self.autonav_stats.backtracks,
                "outcome": self.autonav_stats.outcome,
            }
        return out

    def _kitti(self) -> dict:
        """KITTI-style mean translational error (% of segment length) over sub-segments of 1, 2, 5 and 10 m."""
        tr = self.trajectories()
        truth = tr.pop("truth")
        lengths = [L for L in (1.0, 2.0, 5.0, 10.0) if L < truth.path_length_m()]
        out = {}
        for name, est in tr.items():
            errs = relative_errors(est, truth, lengths, step_frames=4) if lengths else []
            out[name] = {f"{e.length_m:g}m": round(e.translation_error_pct, 3) for e in errs}
        return out

    def _timing(self, vo_ms: list[float]) -> dict:
        out: dict = {"vo_step_ms_median": round(float(np.median(vo_ms)), 1) if vo_ms else None}
        if self.autonav_stats is not None and self.autonav_stats.cycle_ms:
            out["autonav_cycle_ms_median"] = round(float(np.median(self.autonav_stats.cycle_ms)), 1)
        out["realtime_factor"] = round(self.sim.time_s / max(self._wall_s, 1e-9), 1)
        return out

    def _last_goal(self) -> np.ndarray | None:
        for c in reversed(self.sc.commands):
            if isinstance(c, GotoCmd | AutonavCmd):
                return np.array([c.x_m, c.y_m])
        return None

    def _judge(self, m: Metrics) -> tuple[bool, str]:
        if self.error:
            return False, f"run did not complete: {self.error}"
        p = self.sc.passing
        fails: list[str] = []

        def need(ok: bool, text: str) -> None:
            if not ok:
                fails.append(text)

        if p.max_vo_error_pct is not None:
            need(
                m.vo_error_pct is not None and m.vo_error_pct <= p.max_vo_error_pct,
                f"VO error {m.vo_error_pct} % > {p.max_vo_error_pct} %",
            )
        if p.min_dr_error_pct is not None:
            need(m.dr_error_pct >= p.min_dr_error_pct, f"DR error {m.dr_error_pct} % < {p.min_dr_error_pct} %")
        if p.max_dr_error_pct is not None:
            need(m.dr_error_pct <= p.max_dr_error_pct, f"DR error {m.dr_error_pct} % > {p.max_dr_error_pct} %")
        if p.min_vo_convergence_pct is not None:
            need(
                m.vo_convergence_pct is not None and m.vo_convergence_pct >= p.min_vo_convergence_pct,
                f"VO convergence {m.vo_convergence_pct} % < {p.min_vo_convergence_pct} %",
            )
        if p.min_max_slip_pct is not None:
            need(m.max_slip_pct >= p.min_max_slip_pct, f"max slip {m.max_slip_pct} % < {p.min_max_slip_pct} %")
        if p.max_max_slip_pct is not None:
            need(m.max_slip_pct <= p.max_max_slip_pct, f"max slip {m.max_slip_pct} % > {p.max_max_slip_pct} %")
        if p.max_false_positives is not None:
            need(
                m.false_positives <= p.max_false_positives,
                f"{m.false_positives} VO false positives > {p.max_false_positives}",
            )
        if p.expect_halt is not None:
            need(m.halted == p.expect_halt, f"expected a {p.expect_halt} halt, got {m.halted}")
        elif m.halted is not None:
            fails.append(f"unexpected {m.halted} halt")
        if p.expect_dead_reckoning_clear:
            info = self.keep_out_info
            need(
                info is not None
                and info["dead_reckoning_distance_m"] > info["onboard_distance_m"] + 0.1
                and any(info["dead_reckoning_distance_m"] >= z.radius_m for z in self.sc.keep_out),
                "dead reckoning did not believe the rover clear at the keep-out halt",
            )
        if p.goal_within_m is not None:
            need(
                m.goal_distance_m is not None and m.goal_distance_m <= p.goal_within_m,
                f"ended {m.goal_distance_m} m from the goal (> {p.goal_within_m} m)",
            )
        if p.max_body_collisions is not None:
            need(m.body_collisions <= p.max_body_collisions, f"{m.body_collisions} body-collision ticks")
            need(
                m.tall_rock_contacts <= p.max_body_collisions,
                f"{m.tall_rock_contacts} ticks touching rocks taller than {TALL_ROCK_M} m",
            )
        return (not fails, "; ".join(fails) if fails else "all criteria met")


def write_outputs(mission: Mission, metrics: Metrics, out_dir: Path) -> None:
    """metrics.json, trajectories/*.tum, plots/*.png, scenario.json (the resolved config) and events.log."""
    from rover_sim.io import plots

    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "metrics.json").write_text(json.dumps(metrics.deterministic_dict(), indent=2))
    (out_dir / "timing.json").write_text(json.dumps(metrics.timing | {"wall_s": metrics.wall_s}, indent=2))
    (out_dir / "scenario.json").write_text(json.dumps(mission.sc.resolved_dict(), indent=2))
    (out_dir / "events.log").write_text("\n".join(mission.events) + "\n")
    tdir = out_dir / "trajectories"
    tdir.mkdir(exist_ok=True)
    trajs = mission.trajectories()
    for name, tr in trajs.items():
        write_tum(tr, tdir / f"{name}.tum")
    pdir = out_dir / "plots"
    pdir.mkdir(exist_ok=True)
    truth = trajs["truth"]
    dist = truth.cumulative_distance_m()
    errors = {
        n: np.linalg.norm(t.positions_xyz - truth.positions_xyz, axis=1) for n, t in trajs.items() if n != "truth"
    }
    if len(truth) > 1:
        plots.plot_error_vs_distance(dist, errors, pdir / "error_vs_distance.png", title=mission.sc.name)
    keep = [(z.name, z.x_m, z.y_m, z.radius_m) for z in mission.sc.keep_out]
    plots.plot_paths(
        mission.terrain,
        {n: t.positions_xyz for n, t in trajs.items()},
        pdir / "paths.png",
        keep_out=keep,
        title=mission.sc.name,
    )
    if mission.vo_steps:
        ts = np.array([s.t_s for s in mission.vo_steps])
        plots.plot_slip(
            ts,
            {
                "truth": np.array([s.true_slip for s in mission.vo_steps]),
                "VO": np.array([s.vo_slip for s in mission.vo_steps]),
            },
            pdir / "slip.png",
        )


def run_scenario(
    scenario: str | Path | Scenario,
    out_dir: Path | None,
    seed: int | None = None,
    overrides: list[str] | None = None,
    record: bool = True,
    progress: bool = False,
) -> Metrics:
    """Load, run and write one scenario. Ctrl-C or a physics divergence still leaves a valid recording and
    partial metrics (``passed`` false, ``reason`` says why)."""
    from rover_sim.io.recording import RerunRecorder
    from rover_sim.mission.scenario import load_scenario

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides, seed)
    if out_dir is not None:
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
    rec: Recorder = (
        RerunRecorder(out_dir / "recording.rrd", recording_name=sc.name) if (record and out_dir) else NullRecorder()
    )
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(
            desc=sc.name, unit="sim-s", mininterval=1.0, bar_format="{desc}: {n:.0f} sim-s [{elapsed}, {rate_fmt}]"
        )

    def on_progress(t_s: float, _msg: str) -> None:
        if bar is not None and t_s - bar.n >= 1.0:
            bar.update(t_s - bar.n)

    try:
        mission = Mission(sc, rec, on_progress)
        try:
            metrics = mission.run()
        finally:
            mission.renderer.close()
        if out_dir is not None:
            write_outputs(mission, metrics, out_dir)
    finally:
        if bar is not None:
            bar.close()
        rec.close()
    return metrics
