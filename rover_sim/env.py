"""Gymnasium environment: one MER-style drive command per step, stereo images and proprioception back.

Registered as ``rover_sim/MER-v0`` (goal = the scenario's destination, not observed) and ``rover_sim/MERGoal-v0``
(a random goal per episode, given in the observation). Registration is lazy (``entry_point`` string): importing
``rover_sim`` imports gymnasium but not mujoco; the world is built on ``reset``.

Built on the world layer (terrains, RoverSim, SensorSuite, StereoRenderer, drive primitives), the way
``rover_sim.runtime.runner.Mission`` builds a world, and on the mission's camera chain for the sensor profile
(``[sensors] profile``, see :class:`RoverEnv`). The honesty rule holds: observations carry only what the
rover senses (images, IMU, encoders, commanded mast pointing, an operator-given goal); ground truth goes to
``info``. GL: each world owns one EGL context; vector environments must use ``context="spawn"``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium
import numpy as np
from gymnasium import spaces

from rover_sim.env_world import EnvWorld
from rover_sim.errors import PhysicsDiverged

if TYPE_CHECKING:
    from nav.rectify import Rectification
    from rover_sim.render.renderer import StereoRenderer
    from rover_sim.scenario.schema import Scenario
    from rover_sim.sim.physics import RoverSim
    from rover_sim.sim.sensors import SensorSuite
    from rover_sim.world.calibration import RunCalibration

GYRO_RANGE_RAD_S = math.radians(1000.0)  # LN-200 class input range: readings saturate here
ACCEL_RANGE_M_S2 = 40.0 * 9.80665
WHEEL_ANGLE_RANGE_RAD = 1.0e5  # cumulative wheel angle bound of the observation (12.5 km of rolling)
MIN_CURVATURE_PER_M = 0.02  # below this |curvature| (radius > 50 m) an arc is driven as a straight line
SEED_MAX = 2**31 - 1


@dataclass(frozen=True)
class RewardConfig:
    """Reward terms: progress toward the goal (metres gained) per step, bonuses and penalties at termination."""

    progress_weight: float = 1.0
    step_cost: float = 0.0
    goal_bonus: float = 10.0
    collision_penalty: float = 10.0
    keep_out_penalty: float = 10.0
    tilt_penalty: float = 10.0
    diverged_penalty: float = 0.0


def planned_destination(sc: Scenario) -> tuple[float, float] | None:
    """Where the scenario's commands lead on paper (no slip): the last goto/autonav target, else the end point
    of the drive/arc/turn sequence integrated from the start pose; None if the commands do not move the rover."""
    from rover_sim.scenario.commands import ArcCmd, AutonavCmd, DriveCmd, GotoCmd, TurnCmd

    x, y, yaw = sc.start.x_m, sc.start.y_m, math.radians(sc.start.yaw_deg)
    moved = False
    for cmd in sc.commands:
        if isinstance(cmd, DriveCmd):
            x, y, moved = x + cmd.distance_m * math.cos(yaw), y + cmd.distance_m * math.sin(yaw), True
        elif isinstance(cmd, ArcCmd):
            dyaw = cmd.distance_m / cmd.radius_m
            x += cmd.radius_m * (math.sin(yaw + dyaw) - math.sin(yaw))
            y -= cmd.radius_m * (math.cos(yaw + dyaw) - math.cos(yaw))
            yaw, moved = yaw + dyaw, True
        elif isinstance(cmd, TurnCmd):
            yaw += math.radians(cmd.angle_deg)
        elif isinstance(cmd, GotoCmd | AutonavCmd):
            yaw = math.atan2(cmd.y_m - y, cmd.x_m - x)
            x, y, moved = cmd.x_m, cmd.y_m, True
    return (x, y) if moved else None


class RoverEnv(EnvWorld, gymnasium.Env):
    """A MER rover on a scenario's terrain, commanded one drive primitive per step.

    **Action** ``Box(-1, 1, (3,), float32)`` = ``[mode, curvature, amount]``, all normalised:

    * ``mode < 0``: turn in place by ``amount * max_turn_rad`` (> 0 counter-clockwise); ``curvature`` ignored;
    * ``mode >= 0``: drive ``amount * max_drive_m`` metres (negative = backwards) on an Ackermann arc of
      curvature ``curvature * max_curvature_per_m`` (1/m, > 0 turns left); below 0.02 /m it is a straight drive.

    As on MER, the corner wheels steer first, then the wheels roll the commanded amount (wheel odometry), so the
    rover falls short by the slip. A drive stops early when a terminating event (goal, collision, keep-out,
    tilt) happens at one of the 8 Hz ticks.

    **Observation** ``Dict`` (no ground truth): ``"<pair>_left"`` / ``"<pair>_right"`` uint8 ``(H, W)`` greyscale
    images of each stereo pair in ``cameras`` (navcam, hazcam_front, hazcam_rear), always *rectified* (what the
    flight software gave its stereo and VO); ``"imu"`` float32
    ``(imu_samples, 6)``: gyro rad/s and accelerometer m/s^2 (body frame, 100 Hz) taken since the previous step,
    oldest first, the most recent ``imu_samples`` kept, rows ``[:imu_count]`` valid and the rest zero;
    ``"imu_count"`` (Discrete); ``"encoders"`` float32 ``(10,)``: wheel angles (6, cumulative, rad, order lf lm lr
    rf rm rr) then steering angles (4, rad, lf lr rf rr); ``"mast"`` float32 ``(2,)``: commanded pan and elevation
    (rad); with ``goal_in_obs`` also ``"goal"`` float32 ``(2,)``: the goal in the operator-given start frame
    (x ahead, y left, metres), known before the drive as on Mars.

    **Images and the sensor profile** (``[sensors] profile`` of the scenario, "flight" by default): with "ideal"
    they are the exact pinhole pairs (rectified by construction), ``image_noise`` adding the renderer's simple
    noise. With "flight" they follow the mission's chain (:class:`rover_sim.world.world.World`): raw pairs
    through the true lenses (:mod:`rover_sim.render.lens`, a seeded mounting/calibration draw per world,
    :class:`~rover_sim.world.calibration.RunCalibration`) and the CCD image formation
    (:mod:`rover_sim.render.imaging`, always noisy: ``image_noise`` does not apply), the mast stopping within its
    encoder error, then rectified through the *calibrated* models at the commanded pointing
    (:func:`~rover_sim.world.calibration.onboard_stereo_models`, :func:`nav.rectify.rectification`, as
    :meth:`rover_sim.runtime.onboard.Onboard.rectified` does), so calibration errors reach a policy as they reached
    MER's stereo and VO (the shapes are the same in both profiles). ``render()`` (``rgb_array``) is a colour pinhole
    view for people, not a sensor: it is the same in both profiles.

    **Info** (ground truth, never observed): ``position_m``, ``quat_wxyz``, ``tilt_deg``, ``wheel_slip`` (0 where
    not rolling, see ``wheel_slip_valid``), ``wheel_sinkage_m``, ``wheel_load_n``, ``wheel_in_contact``,
    ``body_contacts`` and ``rock_contacts`` (during the step), ``goal_xy``, ``goal_distance_m``, ``termination``
    (``goal``, ``collision``, ``keep_out``, ``tilt``, ``physics_diverged`` or None), ``drive``, ``world_seed``,
    ``image_noise_seed`` (the seed the episode's image noise restarted from).

    **Reward**: metres of progress toward the goal times ``reward.progress_weight``, minus ``step_cost``, plus the
    goal bonus or minus the penalty of the terminating event (:class:`RewardConfig`). Truncated after
    ``max_steps``. Physics divergence terminates the episode (``info["termination"] == "physics_diverged"``).

    **Seeding**: ``reset(seed=s)`` derives the terrain (unless ``fixed_terrain``), IMU and image noise and a random
    goal from ``s``; the same seed and actions give the same observations. The flight profile's camera hardware
    (lens and calibration errors, CCD fixed pattern, mast encoder errors) is drawn from the world's seed (the
    scenario's with ``fixed_terrain``), as a mission run draws it from the scenario seed. A world whose terrain
    seed is unchanged is reused (the rover is placed again), otherwise it is rebuilt and the previous renderer
    closed.

    Usage::

        import gymnasium
        import rover_sim  # registers rover_sim/MER-v0 and rover_sim/MERGoal-v0

        env = gymnasium.make("rover_sim/MER-v0", scenario="wopmay", resolution_px=256, max_steps=50)
        obs, info = env.reset(seed=0)
        print(sorted(obs), info["goal_xy"])  # images, imu, imu_count, encoders, mast; goal (5.0, 2.4)
        for _ in range(5):
            action = [1.0, 0.0, 0.5]  # drive 0.5 m straight ([-1, 0, 0.25]: turn 22.5 deg left in place)
            obs, reward, terminated, truncated, info = env.step(action)
            print(f"{reward:+.2f} m closer, true position {info['position_m'].round(2)}, {info['termination']}")
            if terminated or truncated:
                break
        env.close()
        # vector environments must spawn (never fork after a GL context exists):
        envs = gymnasium.vector.AsyncVectorEnv([lambda: gymnasium.make("rover_sim/MER-v0")] * 2, context="spawn")
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 1}

    def __init__(
        self,
        scenario: str | Path | Scenario = "wopmay",
        overrides: tuple[str, ...] | list[str] = (),
        cameras: tuple[str, ...] = ("navcam",),
        resolution_px: int = 256,
        max_steps: int = 200,
        reward: RewardConfig | dict | None = None,
        render_mode: str | None = None,
        goal: str | tuple[float, float] | None = "scenario",
        goal_in_obs: bool = False,
        goal_tolerance_m: float = 0.3,
        goal_range_m: tuple[float, float] = (2.0, 5.0),
        max_drive_m: float = 1.0,
        max_turn_rad: float = math.pi / 2,
        max_curvature_per_m: float = 2.0,
        speed_m_s: float | None = None,
        imu_samples: int = 4096,
        max_tilt_deg: float = 30.0,
        tall_rock_m: float = 0.25,
        terminate_on_collision: bool = True,
        terminate_on_keep_out: bool = True,
        fixed_terrain: bool = False,
        image_noise: bool | None = None,
        shadows: bool | None = None,
    ) -> None:
        from rover_sim.render.cameras import STEREO_PAIRS
        from rover_sim.scenario.loading import load_scenario
        from rover_sim.scenario.schema import Scenario

        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, list(overrides))
        if not cameras or any(c not in STEREO_PAIRS for c in cameras):
            raise ValueError(f"cameras must be a non-empty subset of {STEREO_PAIRS}, got {cameras!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}")
        if not 0 < max_curvature_per_m <= 1 / 0.3:
            raise ValueError("max_curvature_per_m must be in (0, 1/0.3] (the tightest arc has a 0.3 m radius)")
        if isinstance(goal, str) and goal not in ("scenario", "random"):
            raise ValueError("goal must be 'scenario', 'random', an (x, y) pair in metres or None")
        if goal_in_obs and goal is None:
            raise ValueError("goal_in_obs needs a goal")
        self.cameras = tuple(cameras)
        self.resolution_px = int(resolution_px)
        self.max_steps = int(max_steps)
        self.reward_config = RewardConfig(**reward) if isinstance(reward, dict) else (reward or RewardConfig())
        self.render_mode = render_mode
        self.goal_spec = goal if goal is None or isinstance(goal, str) else (float(goal[0]), float(goal[1]))
        self.goal_in_obs = goal_in_obs
        self.goal_tolerance_m = goal_tolerance_m
        self.goal_range_m = goal_range_m
        self.max_drive_m, self.max_turn_rad, self.max_curvature_per_m = max_drive_m, max_turn_rad, max_curvature_per_m
        self.speed_m_s = speed_m_s or self.scenario.nav.speed_m_s
        self.imu_samples = int(imu_samples)
        self.max_tilt_deg, self.tall_rock_m = max_tilt_deg, tall_rock_m
        self.terminate_on_collision, self.terminate_on_keep_out = terminate_on_collision, terminate_on_keep_out
        self.fixed_terrain = fixed_terrain
        self.image_noise = self.scenario.nav.image_noise if image_noise is None else image_noise
        self.shadows = self.scenario.sun.shadows if shadows is None else shadows

        self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        px, n = self.resolution_px, self.imu_samples
        obs: dict[str, spaces.Space] = {}
        for pair in self.cameras:
            for side in ("left", "right"):
                obs[f"{pair}_{side}"] = spaces.Box(0, 255, shape=(px, px), dtype=np.uint8)
        imu_hi = np.tile(np.array([GYRO_RANGE_RAD_S] * 3 + [ACCEL_RANGE_M_S2] * 3, dtype=np.float32), (n, 1))
        obs["imu"] = spaces.Box(-imu_hi, imu_hi, dtype=np.float32)
        obs["imu_count"] = spaces.Discrete(n + 1)
        enc_hi = np.array([WHEEL_ANGLE_RANGE_RAD] * 6 + [math.pi] * 4, dtype=np.float32)
        obs["encoders"] = spaces.Box(-enc_hi, enc_hi, dtype=np.float32)
        mast_hi = np.array([math.pi, math.pi / 2], dtype=np.float32)
        obs["mast"] = spaces.Box(-mast_hi, mast_hi, dtype=np.float32)
        if goal_in_obs:
            obs["goal"] = spaces.Box(-1.0e4, 1.0e4, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Dict(obs)

        self._geom = None
        self._sim: RoverSim | None = None
        self._renderer: StereoRenderer | None = None
        self._calibration: RunCalibration | None = None
        self._rectifications: dict[str, Rectification] = {}  # pair -> onboard rectification (flight profile)
        self._noise_seed = 0
        self._sensors: SensorSuite | None = None
        self._world_seed: int | None = None
        self._world_sc: Scenario | None = None
        self._goal: np.ndarray | None = None
        self._goal_start_frame = np.zeros(2)
        self._steps = 0
        self._done_reason: str | None = None
        self._last_obs: dict | None = None
        self._last_encoders = np.zeros(10)
        self._imu: list = []
        self._step_events: dict[str, Any] = {}

    def _sample_goal(self, rng: np.random.Generator) -> np.ndarray | None:
        st = self.scenario.start
        if self.goal_spec is None:
            return None
        if self.goal_spec == "scenario":
            dest = planned_destination(self.scenario)
            return None if dest is None else np.array(dest, dtype=float)
        if self.goal_spec == "random":
            r = rng.uniform(*self.goal_range_m)
            bearing = math.radians(st.yaw_deg) + rng.uniform(-math.pi / 3, math.pi / 3)
            nrow, ncol = self.scenario.terrain.grid_shape
            cell = self.scenario.terrain.cell_size_m
            hx, hy = (ncol - 1) * cell / 2 - 1.0, (nrow - 1) * cell / 2 - 1.0
            x = float(np.clip(st.x_m + r * math.cos(bearing), -hx, hx))
            y = float(np.clip(st.y_m + r * math.sin(bearing), -hy, hy))
            return np.array([x, y])
        return np.array(self.goal_spec, dtype=float)

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        from nav.types import RoverGeometry
        from rover_sim.sim.sensors import OdometryErrors, SensorSuite

        super().reset(seed=seed)
        rng = self.np_random
        world_seed = self.scenario.seed if self.fixed_terrain else int(rng.integers(0, SEED_MAX))
        sensor_seed, noise_seed = (int(s) for s in rng.integers(0, SEED_MAX, size=2))
        self._goal = self._sample_goal(rng)
        if self._sim is None or world_seed != self._world_seed:
            self._build_world(world_seed)
        else:
            self._sensors.detach()  # the rover is placed again in the same world: no sampling while it settles
            self._sensors = None
        sim, sc = self._sim, self._world_sc
        assert sim is not None and sc is not None and self._renderer is not None
        self._geom = self._geom or RoverGeometry()
        sim.lock_wheels(list(sc.faults.locked_wheels))
        st = sc.start
        sim.place(st.x_m, st.y_m, math.radians(st.yaw_deg))
        self._mast = np.array([math.radians(sc.nav.mast_pan_deg), math.radians(sc.nav.mast_tilt_deg)])
        self._point_mast(sc)
        sim.step_for(1.0)
        odo = sc.sensors.odometry  # [sensors.odometry]: none in the ideal profile
        if hasattr(sim.law, "sinkage_rolling_radius"):
            sim.law.sinkage_rolling_radius = odo.sinkage_rolling_radius
        errors = OdometryErrors.draw(sensor_seed, **odo.drawn_sizes())
        self._sensors = SensorSuite(sim, seed=sensor_seed, errors=errors)
        self._renderer.reseed_noise(noise_seed if self.image_noise else None)
        if self._renderer.imaging is not None:  # flight: the CCD chain's temporal noise (its fixed pattern stays)
            self._renderer.imaging.reseed_noise(noise_seed)
        self._noise_seed = noise_seed
        if self._goal is not None:
            yaw = math.radians(st.yaw_deg)
            d = self._goal - np.array([st.x_m, st.y_m])
            c, s = math.cos(yaw), math.sin(yaw)
            self._goal_start_frame = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
        self._steps, self._done_reason = 0, None
        self._imu = []
        self._step_events = {"body": set(), "rocks": set(), "stop": None}
        self._drain_sensors()
        self._last_obs = self._observe()
        return self._copy_obs(self._last_obs), self._info(None)

    def step(self, action) -> tuple[dict, float, bool, bool, dict]:
        from rover_sim.sim.drive import execute

        if self._sim is None:
            raise RuntimeError("call reset() before step()")
        if self._done_reason == "physics_diverged":  # nothing left to simulate until reset()
            return self._copy_obs(self._last_obs), 0.0, True, False, self._info(None)
        sim = self._sim
        prim = self._primitive(action)
        d0 = self._goal_distance()
        self._steps += 1
        self._imu = []
        self._step_events = {"body": set(), "rocks": set(), "stop": None}
        drive: dict[str, Any] = {"primitive": repr(prim)}
        try:
            res = execute(sim, prim, self.speed_m_s, on_tick=self._on_tick, geom=self._geom)
            drive.update(completed=res.completed, reason=res.reason, duration_s=res.duration_s)
            drive["wheel_odometry_m"] = res.wheel_odometry_m
            reason = self._step_events["stop"] or self._check(sim)
        except PhysicsDiverged as e:
            drive.update(completed=False, reason=str(e))
            reason = "physics_diverged"
        self._done_reason = reason
        rc = self.reward_config
        if reason == "physics_diverged":
            obs = self._copy_obs(self._last_obs)
            obs["imu"][:] = 0.0
            obs["imu_count"] = np.int64(0)
            return obs, -float(rc.diverged_penalty), True, False, self._info(reason, drive)
        self._drain_sensors()
        self._last_obs = self._observe()
        d1 = self._goal_distance()
        r = -rc.step_cost
        if d0 is not None and d1 is not None:
            r += rc.progress_weight * (d0 - d1)
        r += {
            "goal": rc.goal_bonus,
            "collision": -rc.collision_penalty,
            "keep_out": -rc.keep_out_penalty,
            "tilt": -rc.tilt_penalty,
        }.get(reason, 0.0)
        terminated = reason is not None
        truncated = not terminated and self._steps >= self.max_steps
        return self._copy_obs(self._last_obs), float(r), terminated, truncated, self._info(reason, drive)

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array" or self._renderer is None:
            return None
        return self._renderer.render_rgb(f"{self.cameras[0]}_left")

    def close(self) -> None:
        self._close_world()
        super().close()

    # ------------------------------------------------------------------ internals
    def _primitive(self, action):
        from rover_sim.sim.drive import Arc, Straight, TurnInPlace

        raw = np.asarray(action, dtype=np.float64)
        if raw.size != 3 or not np.all(np.isfinite(raw)):
            raise ValueError(f"action must be 3 finite numbers (mode, curvature, amount) in [-1, 1], got {action!r}")
        a = np.clip(raw.reshape(3), -1.0, 1.0)
        mode, curvature, amount = (float(v) for v in a)
        if mode < 0:
            return TurnInPlace(amount * self.max_turn_rad)
        k = curvature * self.max_curvature_per_m
        distance = amount * self.max_drive_m
        return Straight(distance) if abs(k) < MIN_CURVATURE_PER_M else Arc(1.0 / k, distance)

    def _drain_sensors(self) -> None:
        imu, enc = self._sensors.poll()
        self._imu.extend(imu)
        if enc:
            e = enc[-1]
            self._last_encoders = np.concatenate([e.wheel_angle_rad, e.steer_angle_rad])

    def _on_tick(self, sim: RoverSim) -> str | None:
        self._drain_sensors()
        reason = self._check(sim)
        if reason is not None and self._step_events["stop"] is None:
            self._step_events["stop"] = reason
        return reason

    def _check(self, sim: RoverSim) -> str | None:
        """Terminating events at this instant (ground truth), most serious first; contacts are accumulated."""
        ev = self._step_events
        body = sim.body_contacts()
        rocks = sim.rock_contacts(self.tall_rock_m)
        ev["body"].update(body)
        ev["rocks"].update(rocks)
        if self.terminate_on_collision and (body or rocks):
            return "collision"
        p = sim.position_m()
        if self.terminate_on_keep_out:
            for z in self._world_sc.keep_out:
                if math.hypot(p[0] - z.x_m, p[1] - z.y_m) < z.radius_m:
                    return "keep_out"
        if sim.tilt_deg() > self.max_tilt_deg:
            return "tilt"
        d = self._goal_distance()
        if d is not None and d <= self.goal_tolerance_m:
            return "goal"
        return None

    def _goal_distance(self) -> float | None:
        if self._goal is None:
            return None
        p = self._sim.position_m()
        return float(math.hypot(p[0] - self._goal[0], p[1] - self._goal[1]))

    def _observe(self) -> dict[str, Any]:
        obs: dict[str, Any] = {}
        for pair in self.cameras:
            frame = self._renderer.render_pair(pair)
            left, right = frame.left, frame.right
            rect = self._rectifications.get(pair)
            if rect is not None:  # flight: the raw pair through the onboard (calibrated) rectification
                left, right = rect.apply(left, right)
            obs[f"{pair}_left"], obs[f"{pair}_right"] = left, right
        n = self.imu_samples
        recent = self._imu[-n:]
        imu = np.zeros((n, 6), dtype=np.float32)
        if recent:
            rows = np.array([np.concatenate([s.gyro_rad_s, s.accel_m_s2]) for s in recent])
            hi = self.observation_space["imu"].high[0]
            imu[: len(recent)] = np.clip(rows, -hi, hi)
        obs["imu"] = imu
        obs["imu_count"] = np.int64(len(recent))
        hi = self.observation_space["encoders"].high
        obs["encoders"] = np.clip(self._last_encoders, -hi, hi).astype(np.float32)
        obs["mast"] = self._mast.astype(np.float32)
        if self.goal_in_obs:
            obs["goal"] = self._goal_start_frame.astype(np.float32)
        return obs

    @staticmethod
    def _copy_obs(obs: dict) -> dict:
        return {k: v.copy() for k, v in obs.items()}

    def _info(self, reason: str | None, drive: dict | None = None) -> dict[str, Any]:
        gt = self._sim.ground_truth()
        ev = self._step_events
        info: dict[str, Any] = {
            "position_m": gt.position_m,
            "quat_wxyz": gt.quat_wxyz,
            "tilt_deg": float(gt.tilt_deg),
            "wheel_slip": np.nan_to_num(gt.wheel_slip, nan=0.0),
            "wheel_slip_valid": np.isfinite(gt.wheel_slip),
            "wheel_sinkage_m": gt.wheel_sinkage_m,
            "wheel_load_n": gt.wheel_load_n,
            "wheel_in_contact": gt.wheel_in_contact,
            "body_contacts": sorted(ev["body"]),
            "rock_contacts": sorted(ev["rocks"]),
            "goal_xy": None if self._goal is None else self._goal.copy(),
            "goal_distance_m": self._goal_distance(),
            "termination": reason,
            "sim_time_s": gt.t_s,
            "steps": self._steps,
            "imu_samples_total": len(self._imu),
            "world_seed": self._world_seed,
            "image_noise_seed": self._noise_seed,
        }
        if drive is not None:
            info["drive"] = drive
        return info


ENV_IDS = ("rover_sim/MER-v0", "rover_sim/MERGoal-v0")


def register_envs() -> None:
    """Register the environments with gymnasium (idempotent; lazy: nothing heavy is imported)."""
    from gymnasium.envs.registration import register, registry

    if ENV_IDS[0] not in registry:
        register(id=ENV_IDS[0], entry_point="rover_sim.env:RoverEnv")
    if ENV_IDS[1] not in registry:
        register(id=ENV_IDS[1], entry_point="rover_sim.env:RoverEnv", kwargs={"goal": "random", "goal_in_obs": True})


register_envs()
