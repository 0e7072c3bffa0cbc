"""The EXPERIMENTAL Wong-Reece wheel-soil law (opt-in: ``[physics] soil_model = "wong_reece"``) in isolation, and
slip emerging from it on simulated slopes (every rover built with ``soil_model="wong_reece"``, via bench/mobility).
The default Bekker law is tested in test_terramechanics.py."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from rover_sim.bench.mobility import measure_slip, parked_drift_m, slope_terrain
from rover_sim.errors import ConfigError
from rover_sim.scenario.loading import load_scenario
from rover_sim.sim import terramechanics, terramechanics_wr
from rover_sim.sim.physics import RoverSim
from rover_sim.sim.soil_tables import mobilisation
from rover_sim.sim.terramechanics import pack_inputs
from rover_sim.sim.terramechanics_wr import BEDROCK, DRIFT, MIXED, SAND, WheelSoilLaw

W_N = 108.0  # one sixth of MER's weight on Mars
DT = 0.005


def test_soil_model_selects_the_law_and_the_python_default_is_bekker():
    """RoverSim's own default stays the Bekker patch law (its unit tests pin it); scenarios default to wong_reece."""
    terrain = slope_terrain("sand", 0.0, size_m=(4.0, 4.0))
    default = RoverSim(terrain)
    assert default.soil_model == "bekker" and type(default.law) is terramechanics.WheelSoilLaw
    with pytest.raises(ValueError, match="wong_reece"):
        default.enable_deformation()
    wr = RoverSim(terrain, soil_model="wong_reece")
    assert type(wr.law) is terramechanics_wr.WheelSoilLaw and wr.deform is None
    assert wr.enable_deformation() is wr.deform
    with pytest.raises(ValueError, match="bekker, wong_reece"):
        RoverSim(terrain, soil_model="scm")


def test_scenario_physics_fields_select_the_law():
    sc = load_scenario("wopmay")
    assert (sc.physics.soil_model, sc.physics.deformable) == ("wong_reece", False)  # the default law; ruts opt-in
    assert sc.resolved_dict()["physics"]["soil_model"] == "wong_reece"  # stated in scenario.json and job ids
    old = load_scenario("wopmay", ["physics.soil_model=bekker"])
    assert old.resolved_dict()["physics"]["soil_model"] == "bekker"
    on = load_scenario("wopmay", ["physics.soil_model=wong_reece", "physics.deformable=true"])
    assert (on.physics.soil_model, on.physics.deformable) == ("wong_reece", True)
    assert on.resolved_dict()["physics"]["soil_model"] == "wong_reece"
    with pytest.raises(ConfigError, match="soil_model"):
        load_scenario("wopmay", ["physics.soil_model=scm"])
    with pytest.raises(ConfigError, match="physics.deformable = true needs physics.soil_model = 'wong_reece'"):
        load_scenario("wopmay", ["physics.soil_model=bekker", "physics.deformable=true"])
    with pytest.raises(ConfigError, match=r"spirit_plains_sol.toml.*not supported on a streamed terrain"):
        load_scenario("spirit_plains_sol", ["physics.soil_model=wong_reece", "physics.deformable=true"])


def _steady(law: WheelSoilLaw, slip: float, material: int = 0, v_rim: float = 0.05, seconds: float = 40.0):
    """(longitudinal force, torque) of one wheel rolling with a fixed slip ratio, at steady state."""
    v_x = v_rim * (1.0 - slip)
    inputs = pack_inputs([[0, 0, W_N]], [[0, 0, 0]], [[v_x, 0, 0]], [[1, 0, 0]], [v_rim / law.radius_m])
    for _ in range(int(seconds / DT)):
        f = law.evaluate(inputs, [material], DT)
    return f[0], f[3]


def _one_wheel() -> WheelSoilLaw:
    return WheelSoilLaw(n_wheels=1)


def test_drawbar_pull_rises_monotonically_to_its_peak_and_stays_below_strength():
    law = _one_wheel()
    slips = np.linspace(0.0, 1.0, 41)
    dp = np.array([law.lookup(0, W_N, s)[1] - law.lookup(0, W_N, s)[2] for s in slips])
    peak = int(np.argmax(dp))
    assert peak >= 30  # the peak is at high slip
    assert np.all(np.diff(dp[: peak + 1]) > 0)
    assert dp.max() < np.tan(np.radians(SAND.friction_angle_deg))


def test_steady_force_follows_the_table_and_does_not_depend_on_speed():
    f5, t5 = _steady(_one_wheel(), 0.3, v_rim=0.05)
    f1, t1 = _steady(_one_wheel(), 0.3, v_rim=0.01, seconds=150.0)
    law = _one_wheel()
    z, h, r, t, *_ = law.lookup(0, W_N, 0.3)
    assert f5 == pytest.approx(W_N * (h - r), rel=0.02)
    assert t5 == pytest.approx(W_N * law.radius_m * t, rel=0.02)
    assert f1 == pytest.approx(f5, rel=0.01) and t1 == pytest.approx(t5, rel=0.01)


def test_slip_sinkage_ratio_at_06_is_in_dings_range():
    law = _one_wheel()
    ratio = law.sinkage_m(W_N, 0, 0.6) / law.sinkage_m(W_N, 0, 0.0)
    assert 2.5 <= ratio <= 7.0


def test_locked_wheel_digs_in_and_is_resisted():
    law = _one_wheel()
    assert law.sinkage_m(W_N, 0, -1.0) >= 2.0 * law.sinkage_m(W_N, 0, 0.0)
    inputs = pack_inputs([[0, 0, W_N]], [[0, 0, 0]], [[0.05, 0, 0]], [[1, 0, 0]], [0.0])  # dragged forward
    for _ in range(4000):
        f = law.evaluate(inputs, [0], DT)
    assert f[0] < -0.5 * W_N  # strong resistance against the drag


def test_no_contact_no_force_and_bedrock_does_not_sink():
    law = WheelSoilLaw(n_wheels=2)
    inputs = pack_inputs([[0, 0, 0], [0, 0, W_N]], [[0, 0, 0]] * 2, [[0.05, 0, 0]] * 2, [[1, 0, 0]] * 2, [0.4, 0.4])
    f = law.evaluate(inputs, [0, 1], DT)
    assert f[0:4] == [0.0, 0.0, 0.0, 0.0]
    assert law.state.sinkage_m[1] < 1e-3
    assert not law.state.in_contact[0]


def test_held_wheel_holds_shear_and_vibration_does_not_release_it():
    """A held wheel keeps its mobilised shear; zero-mean jitter does not renew the soil (no creep)."""
    law = _one_wheel()
    push = pack_inputs([[0, 0, W_N]], [[0, 0, 0]], [[-0.002, 0, 0]], [[1, 0, 0]], [0.0])
    for _ in range(200):  # hub pushed back 2 mm
        law.evaluate(push, [0], DT)
    still = pack_inputs([[0, 0, W_N]], [[0, 0, 0]], [[0.0, 0, 0]], [[1, 0, 0]], [0.0])
    f_first = law.evaluate(still, [0], DT)[0]
    for k in range(4000):
        s = 0.002 if k % 2 else -0.002  # +-2 mm/s vibration of the spin and the hub
        law.evaluate(pack_inputs([[0, 0, W_N]], [[0, 0, 0]], [[s, 0, 0]], [[1, 0, 0]], [s / 0.125]), [0], DT)
    f_last = law.evaluate(still, [0], DT)[0]
    assert f_first > 5.0
    assert f_last == pytest.approx(f_first, rel=0.05)


def test_lateral_slip_gives_a_restoring_side_force_with_bulldozing():
    law = _one_wheel()
    inputs = pack_inputs([[0, 0, W_N]], [[0, 0, 0]], [[0.05, -0.01, 0]], [[1, 0, 0]], [0.4])
    for _ in range(4000):
        f = law.evaluate(inputs, [0], DT)
    assert f[1] > 5.0  # pushes back against the sideways (-y) sliding
    assert law.lookup(0, W_N, 0.5)[6] > law.lookup(0, W_N, 0.0)[6] > 0  # side-wall bulldozing grows with sinkage


# ------------------------------------------------------------------ slip emerging in the full simulation


@pytest.mark.parametrize(
    ("material", "slope_deg", "lo", "hi"),
    [("sand", 0.0, 0.0, 0.10), ("sand", 20.0, 0.40, 0.65), ("bedrock", 20.0, 0.0, 0.05)],
)
def test_slip_on_slopes_in_published_band(material, slope_deg, lo, hi):
    row = measure_slip(material, slope_deg, drive_m=1.5, warmup_m=0.4)
    assert lo <= row.slip <= hi, row


@pytest.mark.parametrize("material", ["bedrock", "sand"])
def test_parked_on_30deg_does_not_slide(material):
    assert parked_drift_m(30.0, hold_s=60.0, material=material) < 0.01


def test_same_seed_same_terrain_bytes_and_same_slip():
    a, b = slope_terrain("sand", 15.0, seed=7), slope_terrain("sand", 15.0, seed=7)
    assert a.heights_m.tobytes() == b.heights_m.tobytes()
    assert a.materials.tobytes() == b.materials.tobytes()
    r1 = measure_slip("sand", 15.0, drive_m=1.0, warmup_m=0.3, seed=7)
    r2 = measure_slip("sand", 15.0, drive_m=1.0, warmup_m=0.3, seed=7)
    assert r1.slip == r2.slip and r1.made_good_m == r2.made_good_m


def test_two_scale_shear_curve_reduces_to_janosi_hanamoto_and_keeps_rising():
    """w = 1 (bedrock, mixed, drift) is Janosi-Hanamoto bit for bit; SAND's two-scale curve mobilises its fast part
    within a few K, keeps rising beyond it (concave, below the strength) and starts with the slope 1 / K_0."""
    j = np.linspace(0.0, 0.3, 3001)
    for soil in (BEDROCK, MIXED, DRIFT):
        assert soil.fast_shear_fraction == 1.0
        k = soil.shear_modulus_m
        np.testing.assert_array_equal(mobilisation(j, soil), 1.0 - np.exp(-j / k))
        assert soil.initial_shear_modulus_m == k
    w, k1, k2 = SAND.fast_shear_fraction, SAND.shear_modulus_m, SAND.slow_shear_ratio * SAND.shear_modulus_m
    assert 0.0 < w < 1.0 and k2 > k1
    m = mobilisation(j, SAND)
    assert np.all(np.diff(m) > 0) and np.all(np.diff(m, 2) < 1e-12) and m[-1] < 1.0
    at = mobilisation(np.array([3 * k1, 3 * k2]), SAND)
    assert at[0] < 0.6 and at[1] > 0.9  # short of the strength at 3 K_1 (slow part rising); nearly all at 3 K_2
    slope = mobilisation(np.array([1e-7]), SAND)[0] / 1e-7
    assert slope == pytest.approx(1.0 / SAND.initial_shear_modulus_m, rel=1e-4)
    with pytest.raises(ValueError, match="fast_shear_fraction"):
        dataclasses.replace(SAND, fast_shear_fraction=0.0)
    with pytest.raises(ValueError, match="slow_shear_ratio"):
        dataclasses.replace(SAND, slow_shear_ratio=0.5)


def test_bedrock_params_are_stiffer_than_sand():
    assert BEDROCK.shear_modulus_m < SAND.shear_modulus_m
    assert BEDROCK.friction_angle_deg > SAND.friction_angle_deg
    assert not BEDROCK.deformable and SAND.deformable


def test_shear_state_survives_a_bounce_and_is_renewed_only_by_the_advance():
    """A wheel lifted off for a few steps keeps the soil's shear state (the soil under it is still sheared); it
    decays only as the wheel advances over fresh soil. Resetting it made slip depend on speed (bounces are more
    frequent at 5 cm/s than at 1 cm/s)."""
    law = WheelSoilLaw(n_wheels=1)
    v_rim, slip, r = 0.05, 0.3, law.radius_m
    on = pack_inputs([[0, 0, 108.0]], [[0, 0, 0]], [[v_rim * (1 - slip), 0, 0]], [[1, 0, 0]], [v_rim / r])
    for _ in range(4000):
        law.evaluate(on, [0], 0.005)
    j0, L, f0 = law.j_m[0, 0], law.patch_m[0], law.state.traction_n[0]
    assert j0 / L == pytest.approx(slip, abs=0.01)
    off = pack_inputs([[0, 0, 0.0]], [[0, 0, 0]], [[v_rim * (1 - slip), 0, 0]], [[1, 0, 0]], [v_rim / r])
    for _ in range(4):  # a 20 ms bounce
        law.evaluate(off, [0], 0.005)
    assert law.j_m[0, 0] == pytest.approx(j0 * math.exp(-v_rim / L * 0.02), rel=1e-3)
    law.evaluate(on, [0], 0.005)
    assert f0 > 10.0 and law.state.traction_n[0] > 0.9 * f0  # the thrust is there again on landing
