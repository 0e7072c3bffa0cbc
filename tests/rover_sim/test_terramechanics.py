"""The wheel-soil law in isolation, and slip emerging from it on simulated slopes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rover_sim.bench.slip import measure_slip, parked_drift_m, slope_terrain
from rover_sim.sim.terramechanics import BEDROCK, MATERIALS, SAND, WheelSoilLaw, pack_inputs

W_N = 108.0  # one sixth of MER's weight on Mars
DT = 0.005


def _steady_traction(law: WheelSoilLaw, slip: float, material: int = 0, steps: int = 8000) -> float:
    """Longitudinal force of one wheel rolling at 5 cm/s rim speed with a fixed slip ratio, at steady state."""
    v_rim = 0.05
    v_x = v_rim * (1.0 - slip)
    inputs = pack_inputs([[0, 0, W_N]], [[0, 0, 0]], [[v_x, 0, 0]], [[1, 0, 0]], [v_rim / law.radius_m])
    for _ in range(steps):
        f = law.evaluate(inputs, [material], DT)
    return f[0]


def _one_wheel() -> WheelSoilLaw:
    return WheelSoilLaw(n_wheels=1)


def test_traction_grows_with_slip_and_never_exceeds_shear_strength():
    forces = [_steady_traction(_one_wheel(), s) for s in (0.02, 0.1, 0.3, 0.6, 0.95)]
    assert np.all(np.diff(forces) > 0)
    f_max_upper = W_N * math.tan(math.radians(SAND.friction_angle_deg)) + SAND.cohesion_pa * 0.16 * 0.3
    assert forces[-1] < f_max_upper
    assert forces[0] < 0.3 * forces[-1]


def test_steady_state_matches_janosi_hanamoto_mean_shear():
    """At steady state j = i L, so the force is F_max (1 - K/(iL)(1 - exp(-iL/K))) minus compaction resistance."""
    law = _one_wheel()
    slip = 0.3
    f = _steady_traction(law, slip)
    j = law.j_m[0, 0]
    L = law._patch[0]
    assert j == pytest.approx(slip * L, rel=1e-3)
    x = j / SAND.shear_modulus_m
    z = law.state.sinkage_m[0]
    f_max = W_N * math.tan(math.radians(SAND.friction_angle_deg)) + SAND.cohesion_pa * law.width_m * L
    mobilised = f_max * (1 - (1 - math.exp(-x)) / x)
    # Bekker compaction resistance b (k_c/b + k_phi) z^(n+1) / (n+1)
    r_c = law.width_m * (SAND.k_c / law.width_m + SAND.k_phi) * z ** (SAND.n + 1) / (SAND.n + 1)
    assert f == pytest.approx(mobilised - r_c, rel=1e-3)
    assert 0.005 < z < 0.05


def test_no_contact_no_force_and_bedrock_does_not_sink():
    law = WheelSoilLaw(n_wheels=2)
    inputs = pack_inputs([[0, 0, 0], [0, 0, W_N]], [[0, 0, 0]] * 2, [[0.05, 0, 0]] * 2, [[1, 0, 0]] * 2, [0.4, 0.4])
    f = law.evaluate(inputs, [0, 1], DT)
    assert f[0:3] == [0.0, 0.0, 0.0]
    assert law.state.sinkage_m[1] < 1e-3
    assert not law.state.in_contact[0]


def test_held_wheel_holds_shear_instead_of_creeping():
    """A held wheel (no rolling) keeps its mobilised shear: the force stays while the hub is still."""
    law = _one_wheel()
    push = pack_inputs([[0, 0, W_N]], [[0, 0, 0]], [[-0.001, 0, 0]], [[1, 0, 0]], [0.0])
    for _ in range(100):  # hub pushed back 0.5 mm
        law.evaluate(push, [1], DT)
    still = pack_inputs([[0, 0, W_N]], [[0, 0, 0]], [[0.0, 0, 0]], [[1, 0, 0]], [0.0])
    f_first = law.evaluate(still, [1], DT)[0]
    for _ in range(2000):
        f_last = law.evaluate(still, [1], DT)[0]
    assert f_first > 5.0
    assert f_last == pytest.approx(f_first, rel=1e-9)


def test_lateral_slip_gives_a_restoring_side_force():
    law = _one_wheel()
    inputs = pack_inputs([[0, 0, W_N]], [[0, 0, 0]], [[0.05, -0.01, 0]], [[1, 0, 0]], [0.4])
    for _ in range(2000):
        f = law.evaluate(inputs, [0], DT)
    assert f[1] > 5.0  # pushes back against the sideways (-y) sliding


# ------------------------------------------------------------------ slip emerging in the full simulation


@pytest.mark.parametrize(
    ("material", "slope_deg", "lo", "hi"),
    [("sand", 0.0, 0.0, 0.10), ("sand", 20.0, 0.40, 0.65), ("bedrock", 20.0, 0.0, 0.05)],
)
def test_slip_on_slopes_in_published_band(material, slope_deg, lo, hi):
    row = measure_slip(material, slope_deg, drive_m=1.5, warmup_m=0.4)
    assert lo <= row.slip <= hi, row


def test_parked_on_30deg_bedrock_does_not_slide():
    assert parked_drift_m(30.0, hold_s=60.0) < 0.01


def test_same_seed_same_terrain_bytes_and_same_slip():
    a, b = slope_terrain("sand", 15.0, seed=7), slope_terrain("sand", 15.0, seed=7)
    assert a.heights_m.tobytes() == b.heights_m.tobytes()
    assert a.materials.tobytes() == b.materials.tobytes()
    r1 = measure_slip("sand", 15.0, drive_m=1.0, warmup_m=0.3, seed=7)
    r2 = measure_slip("sand", 15.0, drive_m=1.0, warmup_m=0.3, seed=7)
    assert r1.slip == r2.slip and r1.made_good_m == r2.made_good_m


def test_bedrock_params_are_stiffer_than_sand():
    assert BEDROCK.shear_modulus_m < SAND.shear_modulus_m
    assert BEDROCK.friction_angle_deg > SAND.friction_angle_deg


def test_sinkage_rolling_radius_turns_nominal_rolling_into_braking_in_sand_only():
    """[sensors.odometry] sinkage_rolling_radius: a wheel sunk z rolls on r - z, so a hub moving at r omega (no
    slip by the nominal radius) outruns its rolling speed omega (r - z): the soil brakes it and the slip ratio
    it reports is negative, about -z / (r - z). On bedrock (sinkage below 0.5 mm) it is a few tenths of a %."""
    nominal, sunk = _one_wheel(), _one_wheel()
    sunk.sinkage_rolling_radius = True
    assert _steady_traction(sunk, 0.0) < _steady_traction(nominal, 0.0)
    z = sunk.state.sinkage_m[0]
    assert 0.0 < z < 0.1 * sunk.radius_m
    assert sunk.state.slip[0] == pytest.approx(-z / (sunk.radius_m - z), rel=0.05)
    rock, sunk_on_rock = MATERIALS.index(BEDROCK), _one_wheel()
    sunk_on_rock.sinkage_rolling_radius = True
    _steady_traction(sunk_on_rock, 0.0, material=rock)
    assert sunk_on_rock.state.sinkage_m[0] < 5e-4 and abs(sunk_on_rock.state.slip[0]) < 5e-3
