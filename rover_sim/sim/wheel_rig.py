"""A single-wheel test rig in a soil bin, on the rover's own wheel–soil law and deformable heightfield.

The rig follows the imposed-slip tyre test rigs of Project Chrono (``ChTireTestRig``: a carriage driven at an
imposed travel speed on a prismatic joint, a free vertical slide carrying the normal load as weight, the slip angle
set by a yaw of the wheel assembly, the spindle driven at an imposed rate) and the soil-bin rigs of terramechanics
laboratories (e.g. the CMU single-wheel rig of ``benchmarks/data/cmu_single_wheel``). It is built in MuJoCo around
exactly what the rover uses: the Wong–Reece law (:class:`rover_sim.sim.terramechanics_wr.WheelSoilLaw`, its
compiled kernel), the wheel cylinder on its ground plate (:mod:`rover_sim.sim.ground_plates`) and the deformable
heightfield (:mod:`rover_sim.sim.deform`), so the sinkage measured is the wheel's descent in its own rut.

Mechanism (x is the travel direction, z up):

* ``carriage`` slides along x, position-servoed to ``x0 + v t`` (imposed travel speed ``v``);
* ``hanger`` slides freely along z; the assembly's weight is the imposed normal load (mass ``load / g``);
* the hanger is yawed by ``-beta`` (the slip angle: the angle between the wheel's heading and its travel
  direction), so the wheel travels with a sideways component ``v sin beta`` toward its left;
* the wheel spins about its axle, position-servoed to the imposed rate ``omega`` (the rover's drives are
  position servos on a moving reference too).

Definitions (those of the CMU data set): the slip ratio is ``1 - v / (r omega)`` for ``r omega >= v`` and
``r omega / v - 1`` below it (``-1``: a locked wheel dragged), with ``v`` the carriage speed's magnitude whatever
the slip angle (at 90 deg the wheel still turns at the rate that gives that slip at 0 deg); the drawbar pull is the
horizontal soil force along the heading (positive forward), the lateral force the horizontal soil force along the
axle, positive when it resists the sideways travel; the driving torque is the soil's torque about the axle (the
motor supplies it); the sinkage is the descent of the rim (radius ``r``, the base of any grousers) below the
undisturbed surface. Each quantity is averaged over a steady window of carriage travel (``SETTLE_M`` of travel
first, then ``WINDOW_M`` measured), in a fresh soil bin for every run.

Run-in: the law's shear states relax toward their steady values over a contact length of travel, first order, so
from rest they take about four contact lengths (up to 0.45 m for the CMU wheel dragged) to get within 2 % of them.
A rig run starts them at their steady values for the imposed kinematics (``j_x = i L`` with the law's mobilised
slip ``i``, ``j_y = -v_y L / V`` sideways; :meth:`WheelRig.run_in`), as a long run-in would leave them; the
sinkage, the ruts and the compaction bow still develop over the settling travel. ``tests`` check that a run from
rest over a long travel reaches the same values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from rover_sim.sim.deform import DeformableTerrain
from rover_sim.sim.ground_plates import GroundPlates, add_ground_plates
from rover_sim.sim.soil_tables import SoilParams, WheelParams
from rover_sim.sim.terramechanics_wr import WheelSoilLaw
from rover_sim.sim.wr_kernel import OUT_SINKAGE, OUT_TORQUE, wr_wrenches
from terrains import Material, Terrain

GRAVITY_EARTH_M_S2 = 9.81  # a laboratory soil bin
CELL_M = 0.005  # the bin's heightfield cells: a tenth of the CMU wheel's width
BIN_HALF_Y_M = 0.30
BIN_BEHIND_M, BIN_AHEAD_M = 0.15, 0.30  # soil bin behind the start and beyond the end of the travel (ruts, berms,
# the depth of an earlier rut read ahead of the wheel: none of them may reach the bin's end)
SETTLE_S = 0.5  # the wheel is lowered onto the soil and rests this long before the carriage moves
RAMP_S = 0.2  # carriage speed and wheel rate ramp up over this time
SETTLE_M = 0.15  # carriage travel before the window (more than a contact length: ruts, bow and sinkage settle)
WINDOW_M = 0.10  # carriage travel averaged over
RUT_UPDATE_M = 0.002  # contact travel between rut writes: less than half a cell, so a wheel moving sideways meets
# at most a 1.3 mm rise of its rut's wall before the next write (the rover writes every 2 cm, ahead of its heading)
RUT_DEEPEN_M = 0.0002  # sinkage growth that deepens the rut where the wheel stands: less than the contact's own
# compression, so a deeper rut does not drop the light wheel out of contact (the rover: 1 mm)
WHEEL_MASS_KG = 0.3
ELEVATION_RANGE_M, BASE_Z_M = 0.3, -0.2  # heightfield encoding: ruts far below the surface stay representable
_WHEEL = "w"  # the wheel's name: body ``wheel_w``, as the rover's ``wheel_lf`` ...


@dataclass(frozen=True)
class RigRun:
    """One imposed condition: slip ratio, slip angle, normal load and travel speed."""

    slip: float
    slip_angle_deg: float
    load_n: float
    travel_speed_m_s: float = 0.01


@dataclass(frozen=True)
class RigResult:
    """Steady-window means of one run (forces on the wheel from the soil)."""

    drawbar_pull_n: float
    lateral_force_n: float
    torque_nm: float
    sinkage_m: float  # the rim's descent below the undisturbed surface (the rig's geometry)
    normal_force_n: float  # the ground's normal reaction (the imposed load, to the dynamics' accuracy)
    slip: float  # the slip ratio the rig actually ran at (carriage travel and wheel rotation over the window)
    law_sinkage_m: float  # the law's sinkage (what the rut is written from), for comparison with sinkage_m


def wheel_rate_rad_s(slip: float, travel_speed_m_s: float, radius_m: float) -> float:
    """The spin rate that gives ``slip`` at carriage speed ``v``: ``v / (r (1 - s))`` for ``s >= 0``,
    ``v (1 + s) / r`` for ``s < 0`` (``s = -1`` a locked wheel)."""
    if not -1.0 <= slip < 1.0:
        raise ValueError(f"slip must be in [-1, 1), not {slip}")
    v = abs(travel_speed_m_s)
    return v / (radius_m * (1.0 - slip)) if slip >= 0.0 else v * (1.0 + slip) / radius_m


def slip_ratio(travel_m: float, rim_travel_m: float) -> float:
    """The slip ratio from the distance travelled and the rim's rolled distance ``r * angle`` (same definition)."""
    if rim_travel_m >= travel_m:
        return 1.0 - travel_m / rim_travel_m if rim_travel_m > 0 else 0.0
    return rim_travel_m / travel_m - 1.0


def _rig_xml(wheel: WheelParams, hanger_mass_kg: float, beta_rad: float, timestep_s: float, gravity: float,
             nrow: int, ncol: int, half_x_m: float) -> str:  # fmt: skip
    r = wheel.radius_m
    i_spin = 0.5 * WHEEL_MASS_KG * r * r
    z0 = r + 0.002  # released 2 mm above the surface
    return f"""
<mujoco model="single wheel rig">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{timestep_s}" integrator="implicitfast" gravity="0 0 {-gravity}"/>
  <asset>
    <hfield name="terrain" nrow="{nrow}" ncol="{ncol}" size="{half_x_m} {BIN_HALF_Y_M} {ELEVATION_RANGE_M} 0.1"/>
  </asset>
  <worldbody>
    <geom name="terrain" type="hfield" hfield="terrain" pos="0 0 {BASE_Z_M}" contype="0" conaffinity="0"/>
    <body name="carriage" pos="{BIN_BEHIND_M - half_x_m} 0 {z0}">
      <joint name="carriage_x" type="slide" axis="1 0 0"/>
      <inertial pos="0 0 0" mass="5" diaginertia="0.1 0.1 0.1"/>
      <body name="hanger" euler="0 0 {-beta_rad}">
        <joint name="hanger_z" type="slide" axis="0 0 1"/>
        <inertial pos="0 0 0" mass="{hanger_mass_kg}" diaginertia="0.01 0.01 0.01"/>
        <site name="wheel_{_WHEEL}_hub"/>
        <body name="wheel_{_WHEEL}">
          <joint name="wheel_{_WHEEL}" type="hinge" axis="0 1 0" armature="0.05" damping="0"/>
          <inertial pos="0 0 0" mass="{WHEEL_MASS_KG}" diaginertia="{0.5 * i_spin} {i_spin} {0.5 * i_spin}"/>
          <geom name="wheel_{_WHEEL}" type="sphere" size="{r}" solref="0.08 1" solimp="0.95 0.99 0.001" mass="0"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="carriage_drive" joint="carriage_x" kp="20000" kv="700"/>
    <position name="wheel_{_WHEEL}_drive" joint="wheel_{_WHEEL}" kp="500" kv="20"/>
  </actuator>
  <sensor>
    <contact name="wheel_{_WHEEL}_contact" geom1="wheel_{_WHEEL}" data="found force pos" reduce="netforce" num="1"/>
    <framelinvel name="wheel_{_WHEEL}_hub_vel" objtype="site" objname="wheel_{_WHEEL}_hub"/>
    <framexaxis name="wheel_{_WHEEL}_heading" objtype="site" objname="wheel_{_WHEEL}_hub"/>
    <jointvel name="wheel_{_WHEEL}_rate" joint="wheel_{_WHEEL}"/>
  </sensor>
</mujoco>"""


class WheelRig:
    """One wheel (``wheel``) in a bin of one soil (``soil``): :meth:`run` drives it at an imposed condition.

    The attributes ``model``, ``data``, ``terrain``, ``law`` and ``timestep_s`` are those the deformable terrain
    reads from a simulator (as from :class:`rover_sim.sim.physics.RoverSim`)."""

    def __init__(self, wheel: WheelParams, soil: SoilParams, *, gravity_m_s2: float = GRAVITY_EARTH_M_S2,
                 timestep_s: float = 0.005, deformable: bool = True) -> None:  # fmt: skip
        self.wheel, self.soil, self.gravity_m_s2 = wheel, soil, gravity_m_s2
        self.timestep_s, self.deformable = timestep_s, deformable

    def _build(self, run: RigRun, travel_m: float) -> None:
        """A fresh bin long enough for ``travel_m`` of carriage travel, the rig, the law and the deformable soil."""
        ncol = int(math.ceil((BIN_BEHIND_M + travel_m + BIN_AHEAD_M) / CELL_M)) + 1
        nrow = int(round(2 * BIN_HALF_Y_M / CELL_M)) + 1
        self.terrain = Terrain.from_heights(np.zeros((nrow, ncol)), CELL_M, Material.SAND)
        half_x = self.terrain.half_x_m
        mass = run.load_n / self.gravity_m_s2
        hanger = mass - WHEEL_MASS_KG
        if hanger <= 0.0:
            raise ValueError(f"load {run.load_n} N is below the rig's wheel weight ({WHEEL_MASS_KG} kg)")
        nrow, ncol = self.terrain.heights_m.shape
        xml = _rig_xml(self.wheel, hanger, math.radians(run.slip_angle_deg), self.timestep_s, self.gravity_m_s2,
                       nrow, ncol, half_x)  # fmt: skip
        spec = mujoco.MjSpec.from_string(xml)
        data = (self.terrain.heights_m - BASE_Z_M) / ELEVATION_RANGE_M
        spec.hfield("terrain").userdata = data.astype(np.float32).ravel().tolist()
        add_ground_plates(spec, self.wheel.radius_m, self.wheel.width_m, wheels=(_WHEEL,))
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.plates = GroundPlates(self.model, self.data, self.wheel.radius_m, self.wheel.width_m, wheels=(_WHEEL,))
        self.law = WheelSoilLaw(n_wheels=1, materials=(self.soil,), wheel=self.wheel, mass_share_kg=mass)
        self.deform = (DeformableTerrain(self, (self.soil.deformable,), wheels=(_WHEEL,), update_m=RUT_UPDATE_M,
                                         front_m=self.wheel.radius_m, deepen_m=RUT_DEEPEN_M)
                       if self.deformable else None)  # fmt: skip
        m = self.model
        self._body = np.array([m.body(f"wheel_{_WHEEL}").id], dtype=np.int64)
        self._qx = m.jnt_qposadr[m.joint("carriage_x").id]
        self._qz = m.jnt_qposadr[m.joint("hanger_z").id]
        self._qw = m.jnt_qposadr[m.joint(f"wheel_{_WHEEL}").id]
        self._act_x, self._act_w = m.actuator("carriage_drive").id, m.actuator(f"wheel_{_WHEEL}_drive").id
        a0 = m.sensor_adr[m.sensor(f"wheel_{_WHEEL}_contact").id]
        self._sd = self.data.sensordata[a0 : a0 + 14]  # contact (7), hub velocity (3), heading (3), rate (1)

    def _step(self, forces: np.ndarray, mats: np.ndarray) -> None:
        """One physics step: the law on the sensor block, its wrench on the wheel, the ruts, the plate, mj_step."""
        dt = self.timestep_s
        self.law.evaluate_into(self._sd, mats, dt, forces)
        wr_wrenches(self._sd, forces, self.law.axles, self._body, self.data.xipos, self.data.xfrc_applied)
        if self.deform is not None:
            self.deform.after_law(self, self._sd, mats)
        self.plates.place()
        mujoco.mj_step(self.model, self.data)

    def run_in(self, rim_m_s: float, v_x_m_s: float, v_y_m_s: float, load_n: float) -> None:
        """Set the law's shear states to their steady values for rim speed ``U``, hub speeds ``v_x`` (along the
        heading) and ``v_y`` (toward the wheel's left) under ``load_n``: ``j_x = (U - v_x) L / V`` and
        ``j_y = -v_y L / V`` with ``V`` the largest of the three speeds and ``L`` the table's patch length (the fixed
        points of steps 1-2 of :mod:`rover_sim.sim.terramechanics_wr`)."""
        V = max(abs(rim_m_s), abs(v_x_m_s), abs(v_y_m_s))
        if V <= 0.0:
            return
        i_m = (rim_m_s - v_x_m_s) / V
        patch = self.law.lookup(0, load_n, i_m)[4]
        state = self.law.state_arrays()
        state[0, 0], state[1, 0], state[3, 0] = i_m * patch, -v_y_m_s * patch / V, patch

    def run(self, run: RigRun, settle_m: float = SETTLE_M, window_m: float = WINDOW_M,
            run_in: bool = True) -> RigResult:  # fmt: skip
        """Drive the wheel at ``run`` in a fresh bin; the means over ``window_m`` after ``settle_m`` of travel.
        ``run_in=False`` starts the shear states from rest instead (see the module docstring)."""
        self._build(run, settle_m + window_m)
        m, d, dt = self.model, self.data, self.timestep_s
        r = self.wheel.radius_m
        v = abs(run.travel_speed_m_s)
        omega = wheel_rate_rad_s(run.slip, v, r)
        beta = math.radians(run.slip_angle_deg)
        heading = np.array([math.cos(beta), -math.sin(beta), 0.0])  # the hanger is yawed by -beta
        axle_left = np.array([math.sin(beta), math.cos(beta), 0.0])
        mujoco.mj_kinematics(m, d)
        self.plates.place()
        mujoco.mj_forward(m, d)
        forces, mats = np.zeros((1, 4)), np.zeros(1, dtype=np.int64)
        x_ref, w_ref = float(d.qpos[self._qx]), 0.0
        d.ctrl[self._act_x], d.ctrl[self._act_w] = x_ref, w_ref
        for _ in range(int(round(SETTLE_S / dt))):
            self._step(forces, mats)
        if run_in:
            self.run_in(omega * r, v * math.cos(beta), v * math.sin(beta), run.load_n)
        x_start = float(d.qpos[self._qx])
        acc = np.zeros(6)
        n_acc, t, marks = 0, 0.0, {}
        limit_s = SETTLE_S + 2 * RAMP_S + 2.0 * (settle_m + window_m) / max(v, 1e-6)
        while True:
            t += dt
            ramp = min(t / RAMP_S, 1.0)
            x_ref += ramp * v * dt
            w_ref += ramp * omega * dt
            d.ctrl[self._act_x], d.ctrl[self._act_w] = x_ref, w_ref
            self._step(forces, mats)
            travel = float(d.qpos[self._qx]) - x_start
            if travel < settle_m:
                if t > limit_s:
                    raise RuntimeError("the rig's carriage did not reach its steady window")
                continue
            if "x0" not in marks:
                marks["x0"], marks["w0"] = float(d.qpos[self._qx]), float(d.qpos[self._qw])
            f_soil = forces[0, :3] - self._sd[1:4]  # the law's force plus the ground's normal reaction
            out = self.law.out_state()
            hub_z = float(d.xpos[self._body[0], 2])
            acc += [f_soil @ heading, -(f_soil @ axle_left), out[OUT_TORQUE, 0], -(hub_z - r), f_soil[2],
                    out[OUT_SINKAGE, 0]]  # fmt: skip
            n_acc += 1
            if travel >= settle_m + window_m:
                break
        dp, lat, tq, z, fz, z_law = acc / max(n_acc, 1)
        travel_w = float(d.qpos[self._qx]) - marks["x0"]
        rim_w = (float(d.qpos[self._qw]) - marks["w0"]) * r
        return RigResult(float(dp), float(lat), float(tq), float(z), float(fz), slip_ratio(travel_w, rim_w),
                         float(z_law))  # fmt: skip
