"""Physics stepping of the MER rover with the wheel–soil law, behind named accessors (dm_control style)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from nav.types import STEERED, WHEELS
from rover_sim.errors import PhysicsDiverged
from rover_sim.sim.assembly import ROCK_GEOM_PREFIX, Sun, build_spec
from rover_sim.sim.ground_plates import GroundPlates, add_ground_plates
from rover_sim.sim.ground_truth import GroundTruth
from rover_sim.sim.soil_kernel import apply_wheel_wrenches, materials_under
from rover_sim.sim.stream import release_freed_memory
from rover_sim.sim.terramechanics import WheelSoilLaw, WheelSoilState
from rover_sim.sim.wr_kernel import wr_wrenches

if TYPE_CHECKING:
    from rover_sim.sim.deform import DeformableTerrain
    from rover_sim.sim.stream import TerrainStreamer
    from terrains import Terrain

SOIL_MODELS = ("bekker", "wong_reece")  # the earlier patch law (this class's default), the scenarios' default

WHEEL_RADIUS_M = 0.125
WHEEL_WIDTH_M = 0.16
HOME_BODY_HEIGHT_M = 0.525  # rover-frame origin above flat ground at the home pose
WHEEL_BOTTOMS_ROVER_M = np.array(
    [[x, y, -HOME_BODY_HEIGHT_M] for x in (0.55, 0.0, -0.55) for y in (0.55, -0.55)]
)  # wheel contact points at the home pose, rover frame
ROCK_CONTACT_MARGIN_M = 0.03  # a wheel contact this far above the heightfield is on a rock
MATERIAL_ROCK = 1  # rocks are treated as bedrock by the wheel-soil law
_DIVERGENCE_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQPOS,
)


def yaw_on_slope_quat_wxyz(normal: np.ndarray, yaw_rad: float) -> np.ndarray:
    """Orientation whose z axis is ``normal`` and whose x axis points along ``yaw_rad`` projected on the slope."""
    z = normal / np.linalg.norm(normal)
    heading = np.array([np.cos(yaw_rad), np.sin(yaw_rad), 0.0])
    x = heading - heading.dot(z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z], axis=1)
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, R.ravel())
    return q


class RoverSim:
    """A MER rover on a terrain: physics, the wheel–soil law and named accessors.

    ``soil_law=False`` gives the bare MuJoCo model (frictionless wheels, nothing applied) for speed comparisons.
    ``soil_model`` picks the wheel-soil law: ``"bekker"`` (this class's default, the earlier patch law,
    :mod:`rover_sim.sim.terramechanics`) or ``"wong_reece"`` (the scenarios' default,
    :mod:`rover_sim.sim.terramechanics_wr`, with its own wheel contact, :mod:`rover_sim.sim.ground_plates`), the
    only one that supports :meth:`enable_deformation`. With a ``streamer`` (``[terrain.streamed]``), ``terrain``
    is the first window and the heightfield follows the rover (:mod:`rover_sim.sim.stream`);
    ``texture_fn(window)`` paints each window for the render model (:attr:`spec` is rebuilt for the current
    window when asked for).
    """

    def __init__(
        self,
        terrain: Terrain,
        sun: Sun | None = None,
        soil_law: bool = True,
        texture_rgb: np.ndarray | None = None,
        timestep_s: float | None = None,
        soil_model: str = "bekker",
        streamer: TerrainStreamer | None = None,
        texture_fn: Callable[[Terrain], np.ndarray] | None = None,
    ) -> None:
        if soil_model not in SOIL_MODELS:
            raise ValueError(f"soil_model must be one of {', '.join(SOIL_MODELS)}, not {soil_model!r}")
        self.terrain = terrain
        self.sun = sun or Sun()
        self.streamer, self._texture_fn, self._timestep_override = streamer, texture_fn, timestep_s
        self.terrain_version = 0  # counts window changes (the render model rebuilds when it changes)
        self.soil_model = soil_model
        self._spec = self._build_spec(texture_rgb, paint=False)
        self._spec_version = 0 if streamer is None else -1  # a streamed window is painted when first rendered
        self.model = self._spec.compile()
        if streamer is not None:
            streamer.apply(self.model, terrain)  # the window's true heights (compiling rescales hfield data)
        self.data = mujoco.MjData(self.model)
        self.soil_law_enabled = soil_law
        # the Wong-Reece law computes its own wheel-ground contact: cylinders on ground plates (sim/ground_plates.py)
        self.plates = GroundPlates(self.model, self.data, WHEEL_RADIUS_M, WHEEL_WIDTH_M) if self._has_plates else None
        self.deform: DeformableTerrain | None = None  # attached by enable_deformation() (wong_reece only)
        if soil_model == "wong_reece":
            from rover_sim.sim import terramechanics_wr

            self.law = terramechanics_wr.WheelSoilLaw(WHEEL_RADIUS_M, WHEEL_WIDTH_M)
            self._apply_soil_law = self._apply_soil_law_wr  # the default law's path stays untouched
        else:
            self.law = WheelSoilLaw(WHEEL_RADIUS_M, WHEEL_WIDTH_M)
        n_mat = len(self.law.materials)
        if np.size(terrain.materials) and int(np.max(terrain.materials)) >= n_mat:  # e.g. drift with the default law
            raise ValueError(
                f"the terrain has material code {int(np.max(terrain.materials))} but the {soil_model!r} soil law knows "
                f"only {n_mat} materials (drift ripples need soil_model 'wong_reece')"
            )
        m = self.model
        self._wheel_body = np.array([m.body(f"wheel_{w}").id for w in WHEELS])
        self._wheel_qadr = np.array([m.jnt_qposadr[m.joint(f"wheel_{w}").id] for w in WHEELS])
        self._wheel_act = np.array([m.actuator(f"wheel_{w}_drive").id for w in WHEELS])
        assert (np.diff(self._wheel_act) == 1).all(), "wheel actuators must be contiguous in rover.xml"
        self._steer_act = np.array([m.actuator(f"steer_{w}").id for w in STEERED])
        self._steer_qadr = np.array([m.jnt_qposadr[m.joint(f"steer_{w}").id] for w in STEERED])
        self._mast_act = np.array([m.actuator("mast_pan").id, m.actuator("mast_tilt").id])
        self._mast_qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in ("mast_pan", "mast_tilt")])
        self._rocker_qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in ("rocker_left", "rocker_right")])
        self._bogie_qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in ("bogie_left", "bogie_right")])
        # wheel-soil inputs are grouped in the sensor array: (6 x 7) contact, (6 x 3) hub velocity,
        # (6 x 3) heading, (6,) spin rate -- see models/mer/rover.xml
        a0 = m.sensor_adr[m.sensor("wheel_lf_contact").id]
        self._sd_contact = slice(a0, a0 + 42)
        self._sd_vel = slice(a0 + 42, a0 + 60)
        self._sd_heading = slice(a0 + 60, a0 + 78)
        self._sd_rate = slice(a0 + 78, a0 + 84)
        self._sd_view = self.data.sensordata[a0 : a0 + 84]
        self._forces = np.zeros((6, 3))  # compiled default law: forces and materials per wheel
        self._forces_wr = np.zeros((6, 4))  # the Wong-Reece law's forces and axle torques
        self._mats = np.zeros(6, dtype=np.int64)
        assert m.sensor_adr[m.sensor("wheel_rr_rate").id] == a0 + 83, "sensor layout changed in rover.xml"
        self._imu_gyro = self._sensor_slice("imu_gyro")
        self._imu_accel = self._sensor_slice("imu_accel")
        # cached views into MjData (valid for the lifetime of self.data)
        self._sensordata = self.data.sensordata
        self._xfrc = self.data.xfrc_applied
        self._ctrl = self.data.ctrl
        self._xipos = self.data.xipos
        # terrain lookup for the material under each wheel, and the rock geoms
        self._set_terrain_lookups()
        self.wheel_ref_rad = np.zeros(6)
        self._wheel_free = np.ones(6)  # 0 for a locked (held, dragged) wheel
        self._substep_hook: Callable[[RoverSim], None] | None = None
        self._substep_every = 1
        self._substep_count = 0
        self.reset()

    # ------------------------------------------------------------------ setup
    def _build_spec(self, texture_rgb: np.ndarray | None, paint: bool = True) -> mujoco.MjSpec:
        st = self.streamer
        if st is not None and paint and texture_rgb is None and self._texture_fn is not None:
            texture_rgb = self._texture_fn(self.terrain)
        spec = build_spec(self.terrain, self.sun, texture_rgb=texture_rgb,
                          rock_slots=None if st is None else st.rock_slots,
                          elevation_range_m=None if st is None else st.elevation_range_m)  # fmt: skip
        if self._timestep_override is not None:
            spec.option.timestep = self._timestep_override
        if self._has_plates:
            add_ground_plates(spec, WHEEL_RADIUS_M, WHEEL_WIDTH_M)
        return spec

    @property
    def _has_plates(self) -> bool:
        return self.soil_model == "wong_reece"

    @property
    def spec(self) -> mujoco.MjSpec:
        """The model's spec; for a streamed terrain, of the current window (rebuilt lazily after a move)."""
        if self._spec_version != self.terrain_version:
            self._spec, self._spec_version = self._build_spec(None), self.terrain_version
        return self._spec

    def window_texture_rgb(self) -> np.ndarray | None:
        """The painted terrain texture of the current streamed window (None: not streamed, or no painter)."""
        if self.streamer is None or self._texture_fn is None:
            return None
        return self._texture_fn(self.terrain)

    def _set_terrain_lookups(self) -> None:
        terrain = self.terrain
        self._half_x, self._half_y = terrain.half_x_m, terrain.half_y_m
        self._origin_x, self._origin_y = terrain.origin_xy_m
        self._inv_cell = 1.0 / terrain.cell_size_m
        # the material lookup for the compiled laws (sim/soil_kernel.py)
        self._mat_grid = np.ascontiguousarray(terrain.materials, dtype=np.int64)
        self._h_grid = np.ascontiguousarray(terrain.heights_m, dtype=float)
        self._grid = np.array([self._origin_x, self._origin_y, self._half_x, self._half_y, self._inv_cell], float)
        m = self.model
        self._rock_index = {
            m.geom(f"{ROCK_GEOM_PREFIX}{i:04d}").id: i for i in range(len(terrain.rocks))
        }  # rock geom id -> index into terrain.rocks
        self._is_rock = np.zeros(m.ngeom, dtype=bool)
        self._is_rock[list(self._rock_index)] = True
        self._on_rover = m.geom_bodyid != 0
        self._is_wheel_geom = np.array([m.geom(g).name.startswith("wheel_") for g in range(m.ngeom)])

    def _follow_rover(self) -> None:
        """Streamed terrain: move the heightfield window when the rover has entered another tile."""
        x, y = float(self.data.qpos[0]), float(self.data.qpos[1])
        window = self.streamer.window_for(self.terrain, x, y)
        if window is None:
            return
        self.streamer.apply(self.model, window)
        self.streamer.recentres += 1
        self.terrain = window
        self.terrain_version += 1
        self._set_terrain_lookups()
        if self.plates is not None:
            self.plates.set_terrain()
        release_freed_memory()  # the previous window's arrays (see sim/stream.py)

    def enable_deformation(self) -> DeformableTerrain:
        """Make the heightfield deformable under the wheels (ruts, berms, multipass; see sim/deform.py).
        Only with ``soil_model="wong_reece"`` (it reads that law's sinkage, axles and presink)."""
        if self.soil_model != "wong_reece":
            raise ValueError(f"deformable terrain needs soil_model 'wong_reece', not {self.soil_model!r}")
        if self.streamer is not None:
            raise ValueError("[physics] deformable is not supported with [terrain.streamed] yet; turn one off")
        if self.deform is None:
            from rover_sim.sim.deform import DeformableTerrain

            self.deform = DeformableTerrain(self, tuple(m.deformable for m in self.law.materials))
        return self.deform

    def terrain_heights_m(self) -> np.ndarray:
        """The current ground heights on the terrain's grid (the deformed surface when deformation is on)."""
        return self.deform.heights_m() if self.deform is not None else np.asarray(self.terrain.heights_m).copy()

    def _sensor_slice(self, name: str) -> slice:
        s = self.model.sensor(name)
        return slice(int(s.adr[0]), int(s.adr[0] + s.dim[0]))

    def reset(self) -> None:
        mujoco.mj_resetDataKeyframe(self.model, self.data, self.model.key("home").id)
        self.law.reset()
        self.wheel_ref_rad[:] = 0.0
        self._slide_track: list[tuple[float, np.ndarray]] = []  # (t, position) samples of safety_issue
        self._forward()

    def _forward(self) -> None:
        """``mj_forward``, with the ground plates (if any) placed under the wheels where they now are."""
        if self.plates is not None:
            mujoco.mj_kinematics(self.model, self.data)
            self.plates.place()
        mujoco.mj_forward(self.model, self.data)

    def place(self, x_m: float, y_m: float, yaw_rad: float, settle_s: float = 1.5) -> None:
        """Put the rover at (x, y) with heading ``yaw_rad``, aligned with the local slope, and let it settle."""
        self.reset()
        t = self.terrain
        n = t.normal_at(np.array([x_m]), np.array([y_m])).reshape(3)
        q = yaw_on_slope_quat_wxyz(n, yaw_rad)
        # lowest body height at which every wheel bottom clears the ground (+1 cm), then drop
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, q)
        bottoms = WHEEL_BOTTOMS_ROVER_M @ R.reshape(3, 3).T
        ground = t.height_at(x_m + bottoms[:, 0], y_m + bottoms[:, 1]) - bottoms[:, 2]
        z = float(np.max(ground)) + 0.01
        self.data.qpos[0:3] = [x_m, y_m, z]
        self.data.qpos[3:7] = q
        self.data.qvel[:] = 0.0
        self._forward()
        self.hold()
        if settle_s > 0:
            self.step_for(settle_s)

    def nudge(self, displacement_m: np.ndarray, rotation_vector_rad: np.ndarray) -> None:
        """Move the rover body by ``displacement_m`` (world frame) and turn it by ``rotation_vector_rad`` (axis times
        angle, world frame), velocities kept: a tiny change of the initial state (``physics.perturb_size``)."""
        q = np.zeros(4)
        mujoco.mju_axisAngle2Quat(q, rotation_vector_rad / max(np.linalg.norm(rotation_vector_rad), 1e-300),
                                  float(np.linalg.norm(rotation_vector_rad)))  # fmt: skip
        turned = np.zeros(4)
        mujoco.mju_mulQuat(turned, q, self.data.qpos[3:7].copy())
        self.data.qpos[0:3] += np.asarray(displacement_m, float)
        self.data.qpos[3:7] = turned / np.linalg.norm(turned)
        self._forward()

    # ------------------------------------------------------------------ commands
    def hold(self) -> None:
        """Park: wheel references stay where the wheels are (the non-back-drivable drives hold them)."""
        self.wheel_ref_rad[:] = self.data.qpos[self._wheel_qadr]
        self._ctrl[self._wheel_act] = self.wheel_ref_rad

    def lock_wheels(self, names: list[str]) -> None:
        """Hold these wheels (WHEELS names) whatever the drive command: they are dragged (a failed motor)."""
        self._wheel_free = np.array([0.0 if w in names else 1.0 for w in WHEELS])

    def set_steering_rad(self, angles_rad: np.ndarray) -> None:
        self._ctrl[self._steer_act] = angles_rad

    def set_mast(self, pan_rad: float, tilt_rad: float) -> None:
        self._ctrl[self._mast_act] = [pan_rad, tilt_rad]

    def set_substep_hook(self, hook: Callable[[RoverSim], None] | None, every_n_steps: int = 1) -> None:
        """Call ``hook(sim)`` after every ``every_n_steps`` physics steps (e.g. IMU sampling at 200 Hz)."""
        self._substep_hook, self._substep_every, self._substep_count = hook, max(1, int(every_n_steps)), 0

    # ------------------------------------------------------------------ stepping
    def step(self, wheel_rate_rad_s: np.ndarray | None = None, n_steps: int = 1) -> None:
        """Advance ``n_steps`` physics steps with the wheels commanded at ``wheel_rate_rad_s`` (None = hold)."""
        m, d = self.model, self.data
        dt = m.opt.timestep
        ctrl_wheels = self._ctrl[self._wheel_act[0] : self._wheel_act[0] + 6]
        increment = (
            None if wheel_rate_rad_s is None else np.asarray(wheel_rate_rad_s, dtype=float) * dt * self._wheel_free
        )
        plates = self.plates
        for _ in range(n_steps):
            if increment is not None:
                self.wheel_ref_rad += increment
                ctrl_wheels[:] = self.wheel_ref_rad
            if self.soil_law_enabled:
                self._apply_soil_law(dt)
            if plates is not None:
                plates.place()
            mujoco.mj_step(m, d)
            if self._substep_hook is not None:
                self._substep_count += 1
                if self._substep_count >= self._substep_every:
                    self._substep_count = 0
                    self._substep_hook(self)
        self._check_divergence()
        if self.streamer is not None:
            self._follow_rover()

    def step_for(self, duration_s: float, wheel_rate_rad_s: np.ndarray | None = None) -> None:
        n = int(round(duration_s / self.model.opt.timestep))
        chunk = 200
        while n > 0:
            k = min(chunk, n)
            self.step(wheel_rate_rad_s, k)
            n -= k

    def _apply_soil_law(self, dt: float) -> None:
        """The default law on the sensor block (layout: models/mer/rover.xml), all compiled (sim/soil_kernel.py):
        material under each contact, the law's forces, their wrenches about the wheels' centres of mass."""
        sd = self._sd_view
        materials_under(sd, self._h_grid, self._mat_grid, self._grid, ROCK_CONTACT_MARGIN_M, MATERIAL_ROCK,
                        self._mats)  # fmt: skip
        self.law.evaluate_into(sd, self._mats, dt, self._forces)
        apply_wheel_wrenches(sd, self._forces, self._wheel_body, self._xipos, self._xfrc)

    def _apply_soil_law_wr(self, dt: float) -> None:
        """The Wong-Reece law, compiled (sim/wr_kernel.py): forces plus the soil's torque about each
        axle, applied as wrenches; then the ruts."""
        sd = self._sd_view
        materials_under(sd, self._h_grid, self._mat_grid, self._grid, ROCK_CONTACT_MARGIN_M, MATERIAL_ROCK,
                        self._mats)  # fmt: skip
        self.law.evaluate_into(sd, self._mats, dt, self._forces_wr)
        wr_wrenches(sd, self._forces_wr, self.law.axles, self._wheel_body, self._xipos, self._xfrc)
        if self.deform is not None:
            self.deform.after_law(self, sd, self._mats)

    def safety_issue(
        self, margin_m: float = 0.3, slide_speed_m_s: float = 0.15, window_s: float = 1.0
    ) -> tuple[str, str] | None:
        """``("left_terrain", why)`` when a wheel is within ``margin_m`` of the heightfield's edge or the rover is
        below the ground, ``("slid_down_slope", why)`` when the rover has moved faster than any drive command could
        move it (MER's wheels turn at most 5 cm/s) over the last ``window_s`` (net displacement over that time, from
        the calls' samples: a slide is sustained; a jolt of a wheel in a deep rut or a stick-slip lurch is not):
        the slope is too steep for the soil to hold. None otherwise. Missions check it only with the Wong-Reece
        soil model (see Mission.tick), at 8 Hz."""
        t = self.time_s
        c = self.wheel_centres_m()
        hx, hy = self._half_x - margin_m, self._half_y - margin_m
        if (abs(c[:, 0] - self._origin_x) > hx).any() or (abs(c[:, 1] - self._origin_y) > hy).any():
            p = self.position_m()
            return "left_terrain", f"the rover left the terrain at t = {t:.1f} s (at x {p[0]:.2f}, y {p[1]:.2f} m)"
        ground = self.terrain.height_at(c[:, 0], c[:, 1])
        if (c[:, 2] < ground - 0.2).any():
            return "left_terrain", f"the rover fell through the ground at t = {t:.1f} s"
        track = self._slide_track
        track.append((t, self.position_m()))
        while len(track) > 2 and t - track[1][0] >= window_s:
            track.pop(0)
        t0, p0 = track[0]
        v = float(np.linalg.norm(track[-1][1] - p0)) / (t - t0) if t - t0 >= window_s else 0.0
        if v > slide_speed_m_s:
            return "slid_down_slope", (
                f"the rover slid down the slope at t = {t:.1f} s ({v:.2f} m/s; the wheels drive at most 0.05 m/s):"
                " the soil cannot hold this slope"
            )
        return None

    def _check_divergence(self) -> None:
        d = self.data
        for w in _DIVERGENCE_WARNINGS:
            if d.warning[w].number > 0:
                raise PhysicsDiverged(d.time, f"MuJoCo warning {mujoco.mjtWarning(w).name}")
        if not np.isfinite(d.qpos).all() or not np.isfinite(d.qvel).all():
            raise PhysicsDiverged(d.time, "non-finite state (NaN/Inf in qpos or qvel)")
        if abs(d.qvel[0:3]).max() > 20.0:
            raise PhysicsDiverged(d.time, f"rover speed {np.linalg.norm(d.qvel[0:3]):.1f} m/s is unphysical")

    # ------------------------------------------------------------------ named accessors
    @property
    def time_s(self) -> float:
        return float(self.data.time)

    @property
    def timestep_s(self) -> float:
        return float(self.model.opt.timestep)

    def position_m(self) -> np.ndarray:
        return self.data.qpos[0:3].copy()

    def quat_wxyz(self) -> np.ndarray:
        return self.data.qpos[3:7].copy()

    def rotation(self) -> np.ndarray:
        return self.data.xmat[self.model.body("rover").id].reshape(3, 3).copy()

    def wheel_centres_m(self) -> np.ndarray:
        """(6, 3) wheel-centre positions in the world frame, WHEELS order."""
        return self.data.xpos[self._wheel_body].copy()

    def wheel_angles_rad(self) -> np.ndarray:
        return self.data.qpos[self._wheel_qadr].copy()

    def steer_angles_rad(self) -> np.ndarray:
        return self.data.qpos[self._steer_qadr].copy()

    def mast_angles_rad(self) -> np.ndarray:
        return self.data.qpos[self._mast_qadr].copy()

    def rocker_angles_rad(self) -> np.ndarray:
        return self.data.qpos[self._rocker_qadr].copy()

    def bogie_angles_rad(self) -> np.ndarray:
        return self.data.qpos[self._bogie_qadr].copy()

    def imu_raw(self) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free gyro (rad/s) and accelerometer (m/s^2) at the IMU site, body frame."""
        return self._sensordata[self._imu_gyro].copy(), self._sensordata[self._imu_accel].copy()

    def wheel_soil_state(self) -> WheelSoilState:
        return self.law.state

    def tilt_deg(self) -> float:
        return float(np.degrees(np.arccos(np.clip(self.rotation()[2, 2], -1.0, 1.0))))

    def ground_truth(self) -> GroundTruth:
        s = self.law.state
        return GroundTruth(
            t_s=self.time_s,
            position_m=self.position_m(),
            quat_wxyz=self.quat_wxyz(),
            wheel_slip=s.slip.copy(),
            wheel_sinkage_m=s.sinkage_m.copy(),
            wheel_load_n=s.normal_force_n.copy(),
            wheel_in_contact=self.wheels_in_contact(),
            tilt_deg=self.tilt_deg(),
        )

    def wheels_in_contact(self) -> np.ndarray:
        """(6,) bool: each wheel touches the ground or a rock (from MuJoCo's contact sensors)."""
        return self._sensordata[self._sd_contact].reshape(6, 7)[:, 0] > 0

    def rock_contacts(self, min_height_m: float = 0.0) -> list[tuple[str, str]]:
        """(rover geom, rock name) pairs in contact now, for rocks at least ``min_height_m`` tall (ground truth)."""
        m, d = self.model, self.data
        out = []
        pairs = d.contact.geom[: d.ncon]
        if not self._is_rock[pairs].any():  # the usual case: only wheels on the ground
            return out
        for g1, g2 in pairs:
            for a, b in ((g1, g2), (g2, g1)):
                idx = self._rock_index.get(int(b))
                if idx is not None and m.geom_bodyid[a] != 0 and self.terrain.rocks[idx].height_m >= min_height_m:
                    out.append((m.geom(a).name, self.terrain.rocks[idx].name or m.geom(b).name))
        return out

    def body_contacts(self) -> list[str]:
        """Names of non-wheel rover geoms touching the terrain or a rock (a collision, for GESTALT checks)."""
        m, d = self.model, self.data
        names = []
        pairs = d.contact.geom[: d.ncon]
        if not (~self._is_wheel_geom[pairs] & self._on_rover[pairs]).any():  # the usual case: wheels only
            return names
        for g1, g2 in pairs:
            for a, b in ((g1, g2), (g2, g1)):
                na = m.geom(a).name
                if m.geom_bodyid[b] == 0 and not na.startswith("wheel_") and m.geom_bodyid[a] != 0:
                    names.append(na)
        return names
