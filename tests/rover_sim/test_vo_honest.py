"""VO criteria a do-nothing estimator cannot pass, the failure limit halting a drive, and the suite's regression
gate catching a loosened VO."""

from __future__ import annotations

import textwrap

import pytest

from rover_sim.bench.seeds import Seeds
from rover_sim.runtime.evaluator import false_positive_limit_m
from rover_sim.runtime.run import run_scenario
from rover_sim.scenario.loading import plugin_overrides, scenario_from_dict

STUBS = '''
import numpy as np
from nav.vo import VoResult


class DoNothingVO:
    """Always refuses."""

    def __init__(self, params=None):
        pass

    def reset(self):
        pass

    def step(self, left_u8, right_u8, rig, predicted_motion_rover=None, R_world_rover=None):
        return VoResult("too_few_features", reason="stub")


class EchoVO(DoNothingVO):
    """Returns the dead-reckoned prediction as its measurement."""

    def step(self, left_u8, right_u8, rig, predicted_motion_rover=None, R_world_rover=None):
        pred = np.eye(4) if predicted_motion_rover is None else np.asarray(predicted_motion_rover, dtype=float)
        return VoResult("ok", motion_rover=pred, n_inliers=100)
'''

FEATURELESS = {
    "name": "tiny_featureless",
    "terrain": {"size_m": [8, 6], "cell_size_m": 0.05, "rocks": {"cover_fraction": 0.0}},
    "appearance": {"fine_soil": True},
    "start": {"x_m": -2.0, "y_m": 0.0},
    "nav": {"vo": {"enabled": True, "seek_texture": False, "sanity": {"max_failures": 1}}, "vo_step_m": 0.3},
    "commands": [{"type": "drive", "distance_m": 1.5}],
    "pass": {"expect_halt": "vo_failures"},
}


@pytest.fixture
def stubs(tmp_path, monkeypatch):
    (tmp_path / "stub_vos.py").write_text(textwrap.dedent(STUBS))
    monkeypatch.syspath_prepend(str(tmp_path))
    return {"nothing": "stub_vos:DoNothingVO", "echo": "stub_vos:EchoVO"}


def test_false_positive_is_max_of_2cm_and_5pct_of_the_step():
    assert false_positive_limit_m(0.1) == pytest.approx(0.02)
    assert false_positive_limit_m(0.6) == pytest.approx(0.03)


def test_failure_limit_halts_the_drive(tmp_path):
    m = run_scenario(scenario_from_dict(FEATURELESS), tmp_path, record=False)
    assert m.halted == "vo_failures" and m.passed, m.reason
    assert m.distance_m < 1.2  # stopped before the end of the 1.5 m drive


@pytest.mark.slow
@pytest.mark.parametrize("stub", ["nothing", "echo"])
def test_stub_vo_fails_bench_vo(stubs, stub, tmp_path):
    """A do-nothing VO fails the shadow case (convergence); the echo fails where the wheels slip (msstb)."""
    from rover_sim.bench.vo import bench_vo, runs_of

    stacks, data = bench_vo(None, Seeds((0, 1), "tuning"), out_root=tmp_path, plugins=[stubs[stub]],
                            cases=["shadow", "msstb"], quick=True, workers=0)  # fmt: skip
    per = data["plugins"][stubs[stub]]["profiles"]["flight"]["scenarios"]
    assert not all(r["passed"] for r in per.values()), per
    assert not data["passed"] and set(runs_of(stacks, stubs[stub])) == {"shadow", "msstb"}


def test_do_nothing_vo_fails_the_shadow_case(stubs, tmp_path):
    m = run_scenario("sol235_shadow", tmp_path, record=False, overrides=plugin_overrides(vo=stubs["nothing"]))
    assert not m.passed and m.vo_accepted == 0 and m.vo_refused_reasons == {"too_few_features": 8}


# "Inlier threshold x 10" loosens both of the VO's inlier tests: RANSAC's reprojection threshold (step 6,
# 0.75 -> 7.5 px) and the ML refinement's Mahalanobis outlier gate (step 7, chi^2(3) 16.27 = 4.0 sigma -> 40 sigma,
# i.e. chi^2 x 100). Loosening only the first is not a loosened VO: the second gate re-removes what RANSAC let in.
LOOSENED_VO = ["nav.vo.inlier_threshold_px=7.5", "nav.vo.ml_outlier_chi2=1627"]


@pytest.mark.slow
def test_loosened_vo_trips_the_regression_gate_on_the_shadow_drive(tmp_path):
    """The committed baseline's gate, on the shortest gated scenario over the gate seeds, flags the loosened VO
    (the stock VO passing the same gate is the CI's `bench suite --fast`)."""
    from rover_sim.bench import gate
    from rover_sim.bench.seeded import Case, run_seeded
    from rover_sim.bench.suite import BASELINE_PROFILE, gated_values
    from rover_sim.resources import suite_baseline_path

    base = gate.load_baseline(suite_baseline_path())
    runs = run_seeded([Case("sol235_shadow", "sol235_shadow")], base.seeds, (BASELINE_PROFILE,), tmp_path,
                      overrides=LOOSENED_VO)  # fmt: skip
    verdict = gate.compare(gated_values(runs), base)["sol235_shadow"]["vo_error_pct"]
    assert verdict.regressed, verdict
