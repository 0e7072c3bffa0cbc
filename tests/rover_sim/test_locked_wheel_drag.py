"""A locked (dragged) right-front wheel on the rocker-bogie, with the experimental Wong-Reece law and ruts on.

Why Spirit drove backwards with its right-front wheel locked (from July 2004, about Sol 190, up the Columbia Hills): the
soil's drag on a locked wheel acts at its contact, about 0.43 m below the rocker pivot (models/mer/rover.xml), so
it turns the rocker about its pivot. Leading (driving forward), the drag pushes the wheel down: with a drag of about
0.9 of its load the moment nearly equals the wheel load's about the pivot (0.40 m ahead). The wheel then carries far
more than its static share, the bogie on that side unloads and the rover crawls. Trailing (driving backwards), the
same drag lifts the wheel. This is the mechanics behind ``columbia_hills_drag``'s forward drive crawling or stalling;
the drives here are on flat sand so both directions meet the same ground.
"""

from __future__ import annotations

import numpy as np
import pytest

from rover_sim.bench.mobility import slope_terrain, wr_sim
from rover_sim.sim.drive import MAX_WHEEL_SPEED_M_S, Straight, execute
from rover_sim.sim.physics import RoverSim

RF = 3  # WHEELS order lf, lm, lr, rf, rm, rr
DRIVE_M = 2.0


def _drag_drive(distance_m: float) -> tuple[float, float, float]:
    """(made good m, static RF load N, mean RF load over the second half of the drive N) of a straight drive with
    the right-front wheel locked, flat sand, deformation on."""
    sim = wr_sim(slope_terrain("sand", 0.0, seed=0))
    sim.lock_wheels(["rf"])
    sim.place(0.0, 0.0, 0.0)
    static_n = float(sim.wheel_soil_state().normal_force_n[RF])
    p0 = sim.position_m().copy()
    loads: list[float] = []

    def tick(s: RoverSim) -> None:
        loads.append(float(s.wheel_soil_state().normal_force_n[RF]))

    execute(sim, Straight(distance_m), speed_m_s=MAX_WHEEL_SPEED_M_S, on_tick=tick)
    made_good_m = float(np.linalg.norm(sim.position_m()[:2] - p0[:2]))
    return made_good_m, static_n, float(np.mean(loads[len(loads) // 2 :]))


def test_a_leading_locked_wheel_loads_itself_and_a_trailing_one_does_not():
    fwd_m, static_n, fwd_load_n = _drag_drive(DRIVE_M)
    back_m, static_back_n, back_load_n = _drag_drive(-DRIVE_M)
    assert static_back_n == pytest.approx(static_n, rel=0.05)  # the same rover on the same ground at rest
    # measured with the wheel cylinders on ground plates and the two-scale sand: 1.23x / 0.64x static, 1.79 m
    # backwards against 1.39 m forwards (with the sphere wheels and the earlier sand: 1.95x / 0.85x, 1.73 / 1.05 m)
    assert fwd_load_n >= 1.15 * static_n  # pushed into the soil by its own drag
    assert back_load_n <= 0.85 * static_n  # lifted by it
    assert back_m >= 1.2 * fwd_m  # hence Spirit's backward drives
    assert back_m >= 0.75 * DRIVE_M  # backwards the rover makes good most of the commanded travel
