"""The Wong–Reece law's own wheel contact: cylinders on ground plates (rover_sim/sim/ground_plates.py)."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from rover_sim.bench import mobility
from rover_sim.sim.ground_plates import (
    G_BASE,
    G_CELL,
    G_HALF_WIDTH,
    G_RADIUS,
    G_SCALE,
    G_X0,
    G_Y0,
    PLATE_PREFIX,
    place_plates,
)
from rover_sim.sim.physics import WHEEL_RADIUS_M, WHEEL_WIDTH_M, RoverSim
from terrains import Rock

R, HW = WHEEL_RADIUS_M, 0.5 * WHEEL_WIDTH_M


def _plate(heights: np.ndarray, cell: float, centre: tuple[float, float, float], yaw_rad: float = 0.0):
    """(normal, offset n . x) of the plate place_plates puts under one wheel at ``centre`` heading ``yaw_rad``,
    on heights (rows along y, columns along x) with the grid's corner at (0, 0)."""
    base, scale = float(heights.min()) - 0.1, float(np.ptp(heights)) + 0.2
    hf = ((heights - base) / scale).astype(np.float32).ravel()
    p = np.zeros(7)
    p[G_X0], p[G_Y0], p[G_CELL], p[G_BASE], p[G_SCALE], p[G_RADIUS], p[G_HALF_WIDTH] = 0, 0, cell, base, scale, R, HW
    xpos = np.tile(np.array(centre, dtype=float), (6, 1))  # six wheels at the same place
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # the wheel body: y axis = axle
    pos, quat = np.zeros((6, 3)), np.zeros((6, 4))
    ints = np.array([0, 1, 2, 3, 4, 5, 0, 1, 2, 3, 4, 5, 0, *heights.shape], dtype=np.int64)
    place_plates(xpos, np.tile(rot.reshape(9), (6, 1)), hf, ints, p, pos, quat)
    R_plate = np.zeros(9)
    mujoco.mju_quat2Mat(R_plate, quat[0])
    n = R_plate.reshape(3, 3)[:, 2]
    return n, float(n @ pos[0])


def _grid(n: int = 40, cell: float = 0.04):
    x = np.arange(n) * cell
    return np.meshgrid(x, x)  # X, Y (rows along y)


@pytest.mark.parametrize("slope_deg, azimuth_deg, yaw_deg", [(0, 0, 0), (20, 0, 0), (15, 90, 30), (25, 200, -70)])
def test_plate_is_the_ground_plane_on_a_planar_slope(slope_deg, azimuth_deg, yaw_deg):
    X, Y = _grid()
    g = math.tan(math.radians(slope_deg))
    a = math.radians(azimuth_deg)
    H = 0.3 + g * (math.cos(a) * X + math.sin(a) * Y)
    n, d = _plate(H, 0.04, (0.77, 0.81, 1.0), math.radians(yaw_deg))
    n_true = np.array([-g * math.cos(a), -g * math.sin(a), 1.0])
    n_true /= np.linalg.norm(n_true)
    assert np.allclose(n, n_true, atol=1e-6)
    # the plane holds the ground's points (float32 heightfield encoding: micrometres)
    for x, y in ((0.6, 0.6), (1.0, 0.9), (0.77, 0.81)):
        z = 0.3 + g * (math.cos(a) * x + math.sin(a) * y)
        assert n @ np.array([x, y, z]) == pytest.approx(d, abs=1e-5)


def test_wheel_in_its_rut_sits_on_the_floor_unless_the_ground_ahead_meets_the_rim():
    X, Y = _grid()
    centre = (0.80, 0.80, 0.20)
    in_rut = (np.abs(Y - 0.80) < HW) & (X < 0.80 + 0.06)  # a rut under the tread ending 6 cm ahead of the centre
    shallow = np.where(in_rut, -0.02, 0.0)
    n, d = _plate(shallow, 0.04, centre)
    # 2 cm deep: the rim 6-8 cm ahead has risen 1.6-3 cm: the ground there is lower than the rim, the floor carries
    assert np.allclose(n, [0, 0, 1], atol=1e-9) or n[2] > 0.999
    assert d == pytest.approx(-0.02 * n[2], abs=2e-3)
    deep = np.where(in_rut, -0.06, 0.0)
    _, d_deep = _plate(deep, 0.04, centre)
    # 6 cm deep: the rut's front edge (the first vertex 8 cm ahead, rim risen 2.95 cm) carries the wheel above the floor
    rise_8cm = R - math.sqrt(R * R - 0.08**2)
    assert d_deep > -0.06 + 0.01
    assert d_deep == pytest.approx(-rise_8cm, abs=3e-3)


def test_ground_outside_the_tread_does_not_carry_the_wheel():
    X, Y = _grid()
    berms = np.where(np.abs(Y - 0.80) >= HW + 0.005, 0.05, 0.0)  # 5 cm berms just beside the 16 cm tread
    n, d = _plate(berms, 0.04, (0.80, 0.80, 0.2))
    assert d == pytest.approx(0.0, abs=2e-3)


@pytest.fixture(scope="module")
def rover_on_sand():
    sim = mobility.wr_sim(mobility.slope_terrain("sand", 0.0), deform=False)
    sim.place(0.0, 0.0, 0.0)
    return sim


def test_wheels_are_cylinders_that_do_not_touch_the_heightfield(rover_on_sand):
    sim = rover_on_sand
    m, d = sim.model, sim.data
    hfield = m.geom("terrain").id
    for w in ("lf", "rr"):
        g = m.geom(f"wheel_{w}")
        assert g.type[0] == mujoco.mjtGeom.mjGEOM_CYLINDER
        assert np.allclose(g.size[:2], [R, HW])
    pairs = {tuple(sorted((m.geom(int(a)).name, m.geom(int(b)).name))) for a, b in d.contact.geom[: d.ncon]}
    assert pairs and all(any(p.startswith(PLATE_PREFIX) for p in pair) for pair in pairs)
    assert not any(hfield in (int(a), int(b)) for a, b in d.contact.geom[: d.ncon])
    # standing: the six plates carry the rover's weight, with the law's static sinkage
    weight_n = float(m.body_subtreemass[m.body("rover").id] * -m.opt.gravity[2])
    loads = sim.law.out_state()[0]
    assert loads.sum() == pytest.approx(weight_n, rel=0.02)
    assert (sim.law.out_state()[1] > 0.003).all()


def test_rock_contact_is_its_own_force_not_the_soil_laws():
    terrain = mobility.slope_terrain("sand", 0.0, size_m=(8.0, 6.0))
    rock = Rock(x_m=0.95, y_m=0.55, z_base_m=0.0, shape="hemispheroid", length_m=0.4, width_m=0.4, height_m=0.12)
    sim = RoverSim(dataclasses.replace(terrain, rocks=[rock]), soil_model="wong_reece")
    sim.place(0.0, 0.0, 0.0)
    m, d = sim.model, sim.data
    lf, plate, rock_geom = m.geom("wheel_lf").id, m.geom(f"{PLATE_PREFIX}lf").id, m.geom("rock_0000").id
    seen = False
    for _ in range(400):  # drive the left-front wheel onto the rock
        sim.step(np.full(6, 0.05 / R), 10)
        f_rock, f_plate = np.zeros(3), np.zeros(3)
        for k in range(d.ncon):
            c = d.contact[k]
            f6 = np.zeros(6)
            mujoco.mj_contactForce(m, d, k, f6)
            f_world = c.frame.reshape(3, 3).T @ f6[:3]
            if {c.geom1, c.geom2} == {lf, rock_geom}:
                f_rock += f_world
            elif {c.geom1, c.geom2} == {lf, plate}:
                f_plate += f_world
        if np.linalg.norm(f_rock) > 5.0:
            seen = True
            adr = int(m.sensor("wheel_lf_contact").adr[0])
            sensor = d.sensordata[adr + 1 : adr + 4]
            # the soil law's input is the ground plate's force alone
            assert np.linalg.norm(np.abs(sensor) - np.abs(f_plate)) < 1e-6 * max(1.0, np.linalg.norm(f_plate))
            assert sim.law.out_state()[0][0] < np.linalg.norm(f_plate) + 1.0
            break
    assert seen, "the left-front wheel never loaded the rock"
