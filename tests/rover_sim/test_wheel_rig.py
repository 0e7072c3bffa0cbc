"""The single-wheel rig (rover_sim/sim/wheel_rig.py), the law's single-wheel terms and `bench wheel`'s input.

Fast: the rig's definitions (slip from the imposed rates, sinkage positive down and equal to the rut the law wrote),
the extended law's limits (the rover's soils unchanged where nothing slides sideways; skid, side wall and lateral
sinkage in the right direction), drawbar pull monotone in slip at 0 deg, bad CSV input. Slow: `bench wheel` on a
subset of the CMU rows end to end, and the rig's run-in against a run from rest.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from rover_sim.bench.wheel_data import cmu_data_path, read_tests
from rover_sim.cli.main import app
from rover_sim.errors import ConfigError
from rover_sim.runtime.acceptance import bars
from rover_sim.sim.soil_tables import WheelParams, hegedus_coefficients
from rover_sim.sim.terramechanics_wr import CMU_SAND, K10_MINI_GROUSER, K10_MINI_SMOOTH, SAND, WheelSoilLaw
from rover_sim.sim.wheel_rig import RigRun, WheelRig, slip_ratio, wheel_rate_rad_s
from rover_sim.sim.wr_kernel import side_wall_n

W_N = 108.0


# ------------------------------------------------------------------ the rig's definitions


@pytest.mark.parametrize("slip", [-1.0, -0.7, -0.2, 0.0, 0.23, 0.5, 0.9])
def test_wheel_rate_gives_the_data_sets_slip_definition(slip):
    """slip = 1 - v / (r w) when the rim is faster, r w / v - 1 when slower; v the carriage speed's magnitude."""
    r, v = 0.058, 0.01
    w = wheel_rate_rad_s(slip, v, r)
    rim = r * w
    expected = 1.0 - v / rim if rim >= v else rim / v - 1.0
    assert expected == pytest.approx(slip, abs=1e-12)
    assert slip_ratio(v * 25.0, rim * 25.0) == pytest.approx(slip, abs=1e-12)
    assert wheel_rate_rad_s(slip, -v, r) == w  # the speed's magnitude, whatever the direction
    with pytest.raises(ValueError, match="slip"):
        wheel_rate_rad_s(1.0, v, r)


def test_the_cmu_rates_reproduce_the_recorded_slips():
    """The data's own rows, whatever the slip angle: the commanded wheel rate (deg/s) on the 58 mm wheel at the
    measured carriage speed gives the recorded slip, within 0.06 (the 12 deg/s runs record 0.21-0.23 where 12 deg/s
    gives 0.18: the rig imposes the recorded slip, as the data define it)."""
    for t in read_tests():
        rim = math.radians(float(t.condition.split("|")[2])) * t.geometry.radius_m
        assert slip_ratio(t.travel_speed_m_s, rim) == pytest.approx(t.slip, abs=0.06), t


def test_rig_slip_and_sinkage_definitions():
    """The rig runs at the imposed slip (from its own carriage travel and wheel rotation), carries the imposed load,
    and its sinkage, the rim's descent below the undisturbed surface, is positive and the depth the law wrote its
    rut to (plus the contact's own compression, under a millimetre)."""
    rig = WheelRig(K10_MINI_GROUSER, CMU_SAND)
    res = rig.run(RigRun(0.5, 0.0, 22.0), settle_m=0.06, window_m=0.04)
    assert res.slip == pytest.approx(0.5, abs=0.005)
    assert res.normal_force_n == pytest.approx(22.0, rel=0.01)
    assert res.sinkage_m > 0.005
    assert 0.0 <= res.sinkage_m - res.law_sinkage_m < 0.001
    assert res.drawbar_pull_n > 0.0 and res.torque_nm > 0.0  # a driven wheel pulls and needs driving torque
    dragged = rig.run(RigRun(-1.0, 0.0, 22.0), settle_m=0.06, window_m=0.04)
    assert dragged.slip == pytest.approx(-1.0, abs=0.005)
    assert dragged.drawbar_pull_n < -0.5 * 22.0 and dragged.sinkage_m > res.sinkage_m


def test_rig_lateral_force_resists_the_sideways_travel():
    rig = WheelRig(K10_MINI_SMOOTH, CMU_SAND)
    side = rig.run(RigRun(0.0, 60.0, 20.0), settle_m=0.06, window_m=0.04)
    straight = rig.run(RigRun(0.0, 0.0, 20.0), settle_m=0.06, window_m=0.04)
    assert side.lateral_force_n > 0.2 * 20.0  # positive: against the sideways component of the travel
    assert abs(straight.lateral_force_n) < 1e-6
    assert side.sinkage_m > straight.sinkage_m  # lateral sinkage


# ------------------------------------------------------------------ the law's terms and their limits


def test_rover_soils_unchanged_where_nothing_slides_sideways():
    """SAND on the MER wheel (no rebound, soil-on-soil grousers, Mars gravity): the table the rover reads along its
    travel is the law's from before the single-wheel terms, to the last bit (recorded from commit 6f98f95)."""
    law = WheelSoilLaw(n_wheels=1)
    recorded = {
        -0.5: (0.01462356829237689, -0.38569984314182854, 0.1307447280104686, -0.4036044393461485,
               0.10106154817417778, 0.016169847707868445),
        0.0: (0.005030497358495582, 0.011960486387838542, 0.03955413011187889, 0.012470669936420802,
              0.07557617344606547, 0.012092187751370477),
        0.3: (0.009790959346537426, 0.2736695524569486, 0.061269947806972314, 0.2856945919734535,
              0.08979611154205992, 0.014367377846729586),
        0.9: (0.026864293857169496, 0.5997487586892107, 0.08711045398771165, 0.6326602034972503,
              0.1234872125094558, 0.019757954001512926),
    }  # fmt: skip
    for slip, row in recorded.items():
        assert law.lookup(0, W_N, slip)[:6] == row, slip


def test_smooth_rim_and_rebound_change_only_what_they_name():
    """A grousered wheel ignores the smooth-rim skin friction; a smooth rim pulls less only where it drives the
    soil (slip > 0); a dragged smooth and grousered rim of the same radius behave alike."""
    g = WheelSoilLaw(n_wheels=1, materials=(CMU_SAND,), wheel=K10_MINI_GROUSER)
    g1 = WheelSoilLaw(n_wheels=1, materials=(dataclasses.replace(CMU_SAND, smooth_rim_friction=1.0),),
                      wheel=K10_MINI_GROUSER)  # fmt: skip
    assert g.lookup(0, 22.0, 0.5) == g1.lookup(0, 22.0, 0.5)
    s = WheelSoilLaw(n_wheels=1, materials=(CMU_SAND,), wheel=K10_MINI_SMOOTH)
    s1 = WheelSoilLaw(n_wheels=1, materials=(dataclasses.replace(CMU_SAND, smooth_rim_friction=1.0),),
                      wheel=K10_MINI_SMOOTH)  # fmt: skip
    assert s.lookup(0, 22.0, -0.5) == s1.lookup(0, 22.0, -0.5)
    assert s.lookup(0, 22.0, 0.5)[1] < s1.lookup(0, 22.0, 0.5)[1]  # less thrust
    assert s.lookup(0, 22.0, 0.9)[0] < s1.lookup(0, 22.0, 0.9)[0]  # less slip-sinkage
    with pytest.raises(ValueError, match="smooth_rim_friction"):
        dataclasses.replace(CMU_SAND, smooth_rim_friction=0.0)
    with pytest.raises(ValueError, match="rebound_ratio"):
        dataclasses.replace(CMU_SAND, rebound_ratio=1.0)


def test_skid_sinks_and_bulldozes_for_both_signs_of_slip():
    law = WheelSoilLaw(n_wheels=1, materials=(CMU_SAND,), wheel=K10_MINI_GROUSER)
    z = {s: law.lookup(0, 22.0, s)[0] for s in (-1.0, -0.5, 0.0, 0.5, 0.9)}
    assert z[-1.0] > z[-0.5] > z[0.0] and z[0.9] > z[0.5] > z[0.0]  # slip-sinkage, both signs
    dp = {s: law.lookup(0, 22.0, s)[1] - law.lookup(0, 22.0, s)[2] for s in (-1.0, -0.5)}
    assert dp[-1.0] < dp[-0.5] < 0.0
    assert dp[-1.0] < -math.tan(math.radians(CMU_SAND.friction_angle_deg))  # beyond friction: the front berm


def test_side_wall_bulldozing_over_the_submerged_face():
    """Zero at the surface, growing with depth, past the radius too; the half-buried disc against the closed form
    ``D1 (c pi r^2 / 2 + D2 gamma (2/3) r^3)`` (the half disc's area, and ``int h^2 / 2 dx = 2 r^3 / 3``)."""
    d1, d2, gamma = hegedus_coefficients(CMU_SAND)
    r, c = 0.058, CMU_SAND.cohesion_pa
    f = [side_wall_n(z, r, c, d1, d2, gamma) for z in (0.0, 0.01, 0.03, 0.058, 0.08, 0.11)]
    assert f[0] == 0.0 and all(np.diff(f) > 0)
    half = d1 * (c * math.pi * r * r / 2 + d2 * gamma * (2.0 / 3.0) * r**3)
    assert f[3] == pytest.approx(half, rel=0.01)


def test_lateral_slip_deepens_the_sinkage_and_pushes_back():
    """Sideways sliding deepens the sinkage (isotropic slip-sinkage) and the side wall resists it; with no
    sideways slip nothing changes (the lateral terms vanish)."""
    law = WheelSoilLaw(n_wheels=1, materials=(CMU_SAND,), wheel=K10_MINI_GROUSER)
    from rover_sim.sim.terramechanics import pack_inputs

    def steady(vy: float) -> tuple[float, float, float]:
        law.reset()
        inputs = pack_inputs([[0, 0, 22.0]], [[0, 0, 0]], [[0.01, vy, 0]], [[1, 0, 0]], [0.01 / 0.058])
        for _ in range(6000):
            f = law.evaluate(inputs, [0], 0.005)
        return f[0], f[1], float(law.state.sinkage_m[0])

    fx0, fy0, z0 = steady(0.0)
    fx, fy, z = steady(-0.01)  # 45 deg of sideways travel toward the wheel's right
    assert fy0 == 0.0 and fy > 0.3 * 22.0  # pushes back against the sideways motion
    assert z > 1.2 * z0
    assert z0 == pytest.approx(law.lookup(0, 22.0, 0.0)[0], rel=0.02)


@pytest.mark.parametrize("name", ["grouser", "smooth"])
def test_drawbar_pull_non_decreasing_in_slip_at_0_deg(name):
    """The law's steady drawbar pull at 0 deg (the table the rig reads) over the acceptance's sweep, slip -1 .. 0.9,
    at the wheel's mean 0 deg load in the data: it never falls by more than the bar's tolerance between steps."""
    from rover_sim.bench.wheel import SWEEP_SLIPS, largest_drop

    zero = [t for t in read_tests() if t.wheel == name and t.slip_angle_deg == 0.0]
    law = WheelSoilLaw(n_wheels=1, materials=(CMU_SAND,), wheel=zero[0].geometry)
    load = float(np.mean([t.load_n for t in zero]))
    curve = [(s, law.lookup(0, load, s)[1] - law.lookup(0, load, s)[2]) for s in SWEEP_SLIPS]
    assert largest_drop(curve) <= bars.WHEEL.monotone_tolerance, curve
    assert curve[-1][1] > curve[0][1] + 1.5  # from a dragged wheel's resistance to a driven wheel's pull


# ------------------------------------------------------------------ bench wheel: input and output


def test_data_ships_with_its_licence_and_parses():
    tests = read_tests()
    assert len(tests) == 216
    assert {t.wheel for t in tests} == {"grouser", "smooth"}
    assert {t.slip_angle_deg for t in tests} == {0.0, 30.0, 60.0, 90.0}
    assert all(t.measured is not None for t in tests)
    assert (cmu_data_path().parent / "LICENSE.txt").read_text().startswith("Copyright 2022 Catherine Pavlov")


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("wheel,slip_angle_deg,slip\ngrouser,0,0.1\n", "load_N"),
        ("wheel,slip_angle_deg,slip,load_N\ngrouser,0,abc,20\n", "slip"),
        ("wheel,slip_angle_deg,slip,load_N\ngrouser,120,0.1,20\n", "slip_angle_deg"),
        ("wheel,slip_angle_deg,slip,load_N\ntank,0,0.1,20\n", "wheel"),
        ("wheel,slip_angle_deg,slip,load_N\n", "--data"),
    ],
)
def test_bad_csv_is_one_error_naming_the_file_and_column(tmp_path, text, field):
    p = tmp_path / "tests.csv"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        read_tests(p)
    assert str(p) in str(e.value) and f"'{field}'" in str(e.value)


def test_bench_wheel_cli_bad_input_exits_2_with_one_line(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("wheel,slip\ngrouser,0.2\n")
    r = CliRunner().invoke(app, ["bench", "wheel", "--data", str(p)])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "slip_angle_deg" in lines[0] and str(p) in lines[0]
    r = CliRunner().invoke(app, ["bench", "wheel", "--data", str(tmp_path / "missing.csv")])
    assert r.exit_code == 2 and "no such file" in r.output
    r = CliRunner().invoke(app, ["bench", "wheel", "--wheel", "tank"])
    assert r.exit_code == 2 and "--wheel" in r.output


def test_custom_geometry_columns_and_the_wheel_option(tmp_path):
    p = tmp_path / "mine.csv"
    p.write_text("wheel,slip_angle_deg,slip,load_N,radius_m,width_m,grouser_height_m\nmine,0,0.2,30,0.1,0.08,0.0\n")
    (t,) = read_tests(p)
    assert t.geometry == WheelParams(radius_m=0.1, width_m=0.08, grouser_height_m=0.0, flat_patch_m=0.0)
    assert t.measured is None
    (t,) = read_tests(p, wheel="grouser")
    assert t.geometry == K10_MINI_GROUSER and t.wheel == "grouser"


def test_verdict_lives_in_the_acceptance_module():
    bar = bars.WHEEL
    assert [b.key for b in bar.bands] == ["0-30", "0-60", "0-90"]
    good = {"w": {b.key: {q: 0.0 for q in bars.WHEEL_QUANTITIES} for b in bar.bands}}
    assert bars.judge_wheel(good, {"w": 0.0}) == (True, [])
    bad = json.loads(json.dumps(good))
    bad["w"]["0-30"]["sinkage_mm"] = 9.0
    ok, reasons = bars.judge_wheel(bad, {"w": 0.01})
    assert not ok and len(reasons) == 2 and "0-30" in reasons[0] and "falls" in reasons[1]
    assert bars.judge_wheel({}, {}) == (False, ["nothing to judge: no measured rows and no 0 deg rows"])


@pytest.mark.slow
def test_bench_wheel_end_to_end_on_a_subset(tmp_path):
    """Every slip angle, both wheels, a few rows: the JSON has the documented keys, one row per input row in order."""
    rows = (cmu_data_path()).read_text().splitlines()
    keep = [rows[0]] + [r for k, r in enumerate(rows[1:]) if k % 12 == 0]
    data = tmp_path / "subset.csv"
    data.write_text("\n".join(keep) + "\n")
    out = tmp_path / "wheel.json"
    r = CliRunner().invoke(app, ["bench", "wheel", "--data", str(data), "--json", str(out),
                                 "--png", str(tmp_path / "wheel.png")])  # fmt: skip
    assert r.exit_code in (0, 1), r.output
    doc = json.loads(out.read_text())
    assert set(doc) == {"soil", "wheels", "passed", "reasons", "rows", "rmse"}
    assert len(doc["rows"]) == len(keep) - 1
    assert [row["slip"] for row in doc["rows"]] == [float(x.split(",")[4]) for x in keep[1:]]
    assert set(doc["rows"][0]) == {"wheel", "slip_angle_deg", "slip", "load_N", "drawbar_pull_N", "lateral_force_N",
                                   "sinkage_mm", "torque_Nm", "measured"}  # fmt: skip
    assert set(doc["rmse"]) == {"drawbar_over_load", "lateral_over_load", "sinkage_mm"}
    assert (r.exit_code == 0) == doc["passed"]
    assert (tmp_path / "wheel.png").stat().st_size > 10_000


@pytest.mark.slow
def test_run_in_reaches_what_a_run_from_rest_reaches():
    """The rig's run-in (shear states started at their steady values) against a run from rest over a long travel."""
    rig = WheelRig(K10_MINI_GROUSER, CMU_SAND)
    for run in (RigRun(0.5, 0.0, 22.0), RigRun(0.0, 60.0, 22.0)):
        warm = rig.run(run)
        cold = rig.run(run, settle_m=0.6, run_in=False)
        assert cold.drawbar_pull_n == pytest.approx(warm.drawbar_pull_n, abs=0.02 * 22.0)
        assert cold.lateral_force_n == pytest.approx(warm.lateral_force_n, abs=0.03 * 22.0)
        assert cold.sinkage_m == pytest.approx(warm.sinkage_m, abs=0.0015)


def test_sand_keeps_mars_gravity():
    assert SAND.gravity_m_s2 == pytest.approx(3.711) and CMU_SAND.gravity_m_s2 == pytest.approx(9.81)
