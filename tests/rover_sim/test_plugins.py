"""Plugins: a user's own VO loaded by import path from outside the repository, guarded calls, typed config."""

from __future__ import annotations

import sys
import textwrap

import pytest
from test_runner import TINY  # noqa: E402 (pytest puts this folder on sys.path)

from rover_sim.errors import PluginError
from rover_sim.runtime.plugins import make_stereo, make_vo
from rover_sim.runtime.runner import Mission
from rover_sim.scenario.loading import load_scenario, scenario_from_dict

USER_MODULE = '''
import numpy as np
from nav.vo import VoResult


class RefusingVO:
    """Always refuses: the do-nothing estimator."""

    def reset(self):
        pass

    def step(self, left_u8, right_u8, rig, predicted_motion_rover=None, R_world_rover=None):
        return VoResult("too_few_features", reason="refuses by design")


class MalformedVO(RefusingVO):
    def step(self, left_u8, right_u8, rig, predicted_motion_rover=None, R_world_rover=None):
        return VoResult("ok", motion_rover=np.eye(3), n_inliers=10)


class RaisingVO(RefusingVO):
    def step(self, left_u8, right_u8, rig, predicted_motion_rover=None, R_world_rover=None):
        raise ZeroDivisionError("oops")


class NotAVO:
    pass
'''


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    (tmp_path / "user_vo_plugins.py").write_text(textwrap.dedent(USER_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "user_vo_plugins"
    sys.modules.pop("user_vo_plugins", None)


def _run(impl: str):
    sc = scenario_from_dict(TINY, overrides=[f'nav.vo.impl="{impl}"'])
    mission = Mission(sc)
    try:
        return mission.run()
    finally:
        mission.close()


def test_plugin_from_a_module_outside_the_repo_runs_in_the_loop(user_module):
    m = _run(f"{user_module}:RefusingVO")
    assert m.reason and "run did not complete" not in m.reason
    assert m.vo_steps >= 2 and m.vo_accepted == 0 and m.vo_convergence_pct == 0.0
    assert m.vo_error_pct == m.dr_error_pct  # nothing accepted: the dead-reckoned pose stands


@pytest.mark.parametrize(
    ("cls", "words"),
    [("MalformedVO", ["motion_rover", "4x4"]), ("RaisingVO", ["step()", "ZeroDivisionError", "oops"])],
)
def test_a_misbehaving_plugin_stops_the_run_cleanly_naming_plugin_and_field(user_module, cls, words):
    m = _run(f"{user_module}:{cls}")
    assert not m.passed
    assert m.reason.startswith(f"run did not complete: plugin {user_module}:{cls}")
    for w in words:
        assert w in m.reason
    assert m.distance_m >= 0 and m.sim_s > 0  # partial metrics were still computed


def test_plugin_load_errors_are_one_line_and_name_the_plugin(user_module):
    sc = load_scenario("wopmay")
    cases = {
        "no_such_module_xyz:VO": "cannot import module",
        f"{user_module}:Missing": "has no attribute 'Missing'",
        f"{user_module}:NotAVO": "does not implement nav.protocols.VisualOdometer",
        "not-an-entry-point": "no entry point of that name",
    }
    for impl, text in cases.items():
        spec = sc.nav.vo.model_copy(update={"impl": impl})
        with pytest.raises(PluginError, match=text) as err:
            make_vo(spec)
        assert impl in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(PluginError, match="StereoMatcher"):
        make_stereo(sc.nav.stereo.model_copy(update={"impl": f"{user_module}:RefusingVO"}))


def test_set_reaches_the_algorithm_parameters_and_scenario_json():
    sc = load_scenario(
        "wopmay",
        ["nav.vo.inlier_threshold_px=1.5", "nav.stereo.num_disparities=48", "nav.planner.max_tilt_deg=25"],
    )
    vo = make_vo(sc.nav.vo)
    assert vo.params.inlier_threshold_px == 1.5
    assert make_stereo(sc.nav.stereo).params.num_disparities == 48
    resolved = sc.resolved_dict()["nav"]
    assert resolved["vo"]["params"]["inlier_threshold_px"] == 1.5
    assert resolved["planner"]["params"]["max_tilt_deg"] == 25
    # scenario.json loads back to the same scenario
    assert scenario_from_dict(sc.resolved_dict()) == sc


def test_bad_parameter_names_the_field_and_the_range():
    from rover_sim.errors import ConfigError

    with pytest.raises(ConfigError, match="nav.vo.params.*window_px=4: use an odd window"):
        load_scenario("wopmay", ["nav.vo.window_px=4"])
    with pytest.raises(ConfigError, match="nav.vo.params.bogus"):
        load_scenario("wopmay", ["nav.vo.bogus=1"])


@pytest.mark.parametrize("case", ["short", pytest.param("msstb", marks=pytest.mark.slow)])
def test_bench_vo_runs_the_example_vo_beside_mer_vo(tmp_path, monkeypatch, capsys, case):
    """`rover-sim bench vo --vo rover_sim.examples.opencv_vo:OpenCvStereoVO` on one case over seeds: every variant's
    table, the plugin's JSON beside MER VO's. The fast form runs a short sandy-slope case (the tiny scenario, 1.2 m
    with 4 VO steps); `-m slow` runs MSSTB."""
    import json

    from rover_sim.bench.seeds import Seeds
    from rover_sim.bench.vo import BUILTIN, FULL_POSE, VO_CASES, bench_vo, runs_of
    from rover_sim.examples import EXAMPLE_VO

    monkeypatch.chdir(tmp_path)  # the example ships inside the package: found from any working directory
    scenarios = dict(VO_CASES)
    if case == "short":
        short = dict(TINY, commands=[{"type": "drive", "distance_m": 1.2}], name="tiny_vo_case")
        scenarios = {"short": scenario_from_dict(short)}
    out = tmp_path / "vo.json"
    plugin = EXAMPLE_VO
    seeds = (0,) if case == "short" else (0, 1)
    stacks, _ = bench_vo(str(out), Seeds(seeds, "tuning"), out_root=tmp_path, plugins=[plugin], cases=[case],
                         case_scenarios=scenarios, workers=0)  # fmt: skip
    table = capsys.readouterr().out
    for label, profile in ((BUILTIN, "flight"), (BUILTIN, "ideal"), (FULL_POSE, "flight"), (plugin, "flight")):
        assert f"stack: {label}, sensors profile: {profile}, seeds: {','.join(map(str, seeds))} (tuning)" in table
    saved = json.loads(out.read_text())
    mer = saved["profiles"]["flight"]["scenarios"][case]
    ours = saved["plugins"][plugin]["profiles"]["flight"]["scenarios"][case]
    assert set(saved["profiles"]) == {"flight", "ideal"} and saved["seeds"] == list(seeds)
    assert mer["passed"] and mer["metrics"]["vo_convergence_pct"]["median"] == 100.0
    assert set(mer["metrics"]["vo_error_pct"]["per_seed"]) == {str(s) for s in seeds}
    # the example VO really ran in the loop (its steps were judged), and did better than dead reckoning
    runs = runs_of(stacks, plugin)[case]
    for seed in seeds:
        m = runs.metrics[seed]
        assert m["vo_convergence_pct"] is not None and m["vo_convergence_pct"] > 50.0
        assert m["vo_error_pct"] < m["dr_error_pct"]
    assert ours["metrics"]["vo_error_pct"]["median"] is not None
    assert saved["scorecard"][plugin]["summary"] is not None


def test_installed_packages_register_plugins_by_entry_point(user_module, monkeypatch):
    from importlib.metadata import EntryPoint

    from rover_sim.runtime import plugins

    ep = EntryPoint(name="refusing_vo", value=f"{user_module}:RefusingVO", group=plugins.ENTRY_POINT_GROUP)
    monkeypatch.setattr(plugins, "entry_points", lambda group: [ep] if group == plugins.ENTRY_POINT_GROUP else [])
    spec = load_scenario("wopmay").nav.vo.model_copy(update={"impl": "refusing_vo"})
    vo = make_vo(spec)
    assert type(vo.impl).__name__ == "RefusingVO"
