"""One judge (rover_sim.runtime.acceptance): every benchmark's console table, JSON, JUnit and exit status come from
the same verdict; and every command fails fast, saying why, before any run (cli/preflight.py)."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from contextlib import contextmanager
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

from rover_sim.apps.descent import DescentConditions, DescentRun, DescentTruth
from rover_sim.cli.main import app
from rover_sim.cli.preflight import dir_problem, file_problem, plugin_problem
from rover_sim.cli.status import ExitStatus
from rover_sim.runtime import acceptance
from rover_sim.runtime.acceptance import bars


def _junit_cases(path) -> dict[str, ET.Element]:
    return {c.get("name"): c for c in ET.parse(path).getroot().iter("testcase")}


# ---------------------------------------------------------------------------------------------- bench dimes
class _FakeDescentWorld:
    """Descents without terrain synthesis or rendering: the frame carries the true velocity for the fake
    estimator below (a stand-in for the images; the bench's bookkeeping, verdict and outputs run for real)."""

    def __init__(self, terrain_seed: int) -> None:
        self.terrain_seed = terrain_seed

    @classmethod
    @contextmanager
    def build(cls, terrain_seed: int, *_args, **_kw):  # noqa: ANN206
        yield cls(terrain_seed)

    def fly(self, conditions: DescentConditions) -> DescentRun:
        v = np.zeros((3, 3))
        v[-1, :2] = conditions.wind_mps
        truth = DescentTruth(np.zeros(3), np.zeros((3, 3)), v, np.tile(np.eye(3), (3, 1, 1)), np.full(3, 1700.0))
        return DescentRun((v[-1, :2].copy(),), truth, conditions, self.terrain_seed)


def _stingy_estimator(accept: int):
    """A descent estimator that answers (exactly) for the first ``accept`` descents and refuses every other."""
    seen = {"n": 0}

    def estimate(frames, params):  # noqa: ANN001, ANN202
        seen["n"] += 1
        ok = seen["n"] <= accept
        return SimpleNamespace(velocity_mps=frames[0] if ok else None, reason="" if ok else "refused by design",
                               fire_tirs=False, elapsed_ms=1.0)  # fmt: skip

    return estimate


def test_dimes_accepting_1_of_50_descents_exits_1_and_its_junit_says_why(tmp_path, monkeypatch) -> None:
    """The accepted-fraction floor is judged where the exit status and JUnit come from (it used to be in the JSON
    only, so 1 accepted descent of 50 exited 0)."""
    import rover_sim.bench.dimes as dimes

    monkeypatch.setattr(dimes, "DescentWorld", _FakeDescentWorld)
    monkeypatch.setattr(dimes, "estimate_velocity", _stingy_estimator(accept=1))
    junit, out = tmp_path / "dimes.xml", tmp_path / "dimes.json"
    r = CliRunner().invoke(app, ["bench", "dimes", "--runs", "50", "--junit", str(junit), "--json", str(out)])
    assert r.exit_code == ExitStatus.FAILED, (r.exit_code, r.output, r.exception)
    cases = _junit_cases(junit)
    failure = cases["accepted fraction"].find("failure")
    assert failure is not None and failure.get("message") == "1 of 50 descents accepted (2% < 90%)"
    for name in ("horizontal velocity error 1-sigma", "descents", "featureless plain rejected"):
        assert cases[name].find("failure") is None, name  # the one accepted estimate is exact: only the floor fails
    written = json.loads(out.read_text())
    assert written["passed"] is False and written["reasons"] == ["1 of 50 descents accepted (2% < 90%)"]
    assert "| accepted fraction | 1/50 (2%) | >= 90% | NO: 1 of 50 descents accepted (2% < 90%) |" in r.output


def test_dimes_verdict_floor_is_a_fraction_of_the_descents() -> None:
    base = {"velocity_error_1sigma_mps": 0.6, "featureless_rejected": True}
    assert bars.dimes_verdict(base | {"runs": 50, "accepted": 45}).passed
    assert not bars.dimes_verdict(base | {"runs": 50, "accepted": 44}).passed
    v = bars.dimes_verdict(base | {"runs": 40, "accepted": 40})
    assert v.reasons == ["descents 40 (need >= 50)"]
    none = bars.dimes_verdict(base | {"runs": 50, "accepted": 0, "velocity_error_1sigma_mps": None})
    assert "horizontal velocity error 1-sigma not measured (need <= 1.50 m/s)" in none.reasons


@pytest.mark.slow
def test_dimes_rendered_descents_with_an_estimator_accepting_1_of_50_exit_1(tmp_path, monkeypatch) -> None:
    """The same on rendered descents (about 5 min): the real estimator answers the first descent only."""
    import rover_sim.bench.dimes as dimes

    real = dimes.estimate_velocity
    seen = {"n": 0}

    def first_only(frames, params):  # noqa: ANN001, ANN202
        seen["n"] += 1
        res = real(frames, params)
        return res if seen["n"] == 1 else SimpleNamespace(velocity_mps=None, reason="refused by design",
                                                         fire_tirs=False, elapsed_ms=res.elapsed_ms)  # fmt: skip

    monkeypatch.setattr(dimes, "estimate_velocity", first_only)
    junit = tmp_path / "dimes.xml"
    r = CliRunner().invoke(app, ["bench", "dimes", "--runs", "50", "--junit", str(junit)])
    assert r.exit_code == ExitStatus.FAILED, (r.exit_code, r.output, r.exception)
    failure = _junit_cases(junit)["accepted fraction"].find("failure")
    assert failure is not None and "1 of 50 descents accepted" in failure.get("message")


# ---------------------------------------------------------------------------------------------- other benches
def test_every_bench_bar_is_judged_in_acceptance() -> None:
    """Bars that used to live inline in the benchmark modules, now typed bars with verdicts (spot checks)."""
    km = {"name": "traverse_1km", "distance_m": 1004.0, "peak_rss_mb": 1500.0, "rss_100m_mb": 1200.0,
          "rss_end_mb": 1300.0, "recording_mb": 40.0, "realtime_factor": 18.0}  # fmt: skip
    assert bars.traverse_verdict(km).passed
    slow = bars.traverse_verdict(km | {"realtime_factor": 9.0})
    assert slow.reasons == ["real-time factor 9 (need >= 15)"]
    assert bars.slip_check("sand", 18.0, 0.52).passed and not bars.slip_check("sand", 18.0, 0.3).passed
    assert not bars.slip_check("bedrock", 10.0, 0.08).passed  # outcrop <= 20 deg: <= 5 %
    field = {"seed": 4, "reached": True, "goal_distance_m": 0.4, "collision": True, "body_collisions": 0,
             "tall_rock_contacts": 12}  # fmt: skip
    assert bars.autonav_field_verdict(field).reasons == ["0 body-collision ticks, 12 tall-rock ticks"]
    assert bars.render_verdict({"stereo_pair_256_shadows_ms": 55.0}).reasons == [
        "256x256 pair with shadows 55.0 ms > 40 ms"
    ]


MOBILITY = {
    "rows": [{"material": "sand", "slope_deg": 0.0, "slip": 0.03}, {"material": "sand", "slope_deg": 18.0, "slip": 0.5},
             {"material": "bedrock", "slope_deg": 20.0, "slip": 0.02}],
    "slip_fine_sand": {"17": 0.45, "18": 0.5, "19": 0.55, "20": 0.6}, "max_step_pp_10_25": 5.0,
    "backslide_slope_deg": 28.0, "speed_effect_pp": {"15": 1.0, "20": 2.0}, "sinkage_ratio_i06": 3.5,
    "parked_30deg_bedrock_drift_m": 0.002, "parked_30deg_sand_drift_m": 0.004,
    "cross_slope_drift_m_per_m": {"sand": {"10": 0.01, "15": 0.02, "20": 0.04, "25": 0.08}, "bedrock": {"20": 0.005}},
    "locked_wheel_sinkage_ratio": 2.5, "ruts": {"rut_depth_ratio": 0.9, "second_pass_sinkage_ratio": 0.6},
    "bedrock_unchanged": True, "deformation_realtime_factor": 60.0, "deformation_bare_ratio": 0.7,
}  # fmt: skip


def test_mobility_verdict_names_each_unmet_bar() -> None:
    """`bench slip`'s checks (once inline in bench/mobility.py) judged in acceptance, each failure with its value."""
    assert bars.mobility_verdict(MOBILITY).passed
    v = bars.mobility_verdict(MOBILITY | {"locked_wheel_sinkage_ratio": 1.4, "backslide_slope_deg": None})
    assert v.reasons == ["first slope with slip >= 100 % none (need 25-32 deg (Spirit Sol 206: 125 % > 25 deg))",
                         "locked right-front sinkage / free wheels (held out) 1.40 (need >= 2.00)"]  # fmt: skip
    assert v.checks[0].name == "sand 0 deg" and len(v.checks) == 3 + 16


# ---------------------------------------------------------------------------------------------- fail fast
def test_a_typo_in_vo_stops_the_suite_before_any_run_and_writes_the_junit(tmp_path) -> None:
    """`bench suite --fast --vo nosuch:X --junit P`: exit 2, P holds one error case saying why."""
    junit = tmp_path / "ci" / "suite.xml"
    r = CliRunner().invoke(app, ["bench", "suite", "--fast", "--vo", "nosuch_vo_module:X", "--junit", str(junit)])
    assert r.exit_code == ExitStatus.BAD_INPUT, (r.exit_code, r.output, r.exception)
    assert "Traceback" not in r.output and "stack: builtin" not in r.output  # nothing ran
    line = r.stderr.strip()
    assert line.startswith("error: --vo: plugin nosuch_vo_module:X") and "cannot import module" in line
    root = ET.parse(junit).getroot()
    (case,) = list(root.iter("testcase"))
    error = case.find("error")
    assert error is not None and error.get("message").startswith("bad input: --vo: plugin nosuch_vo_module:X")
    assert root.find("testsuite").get("errors") == "1"


def test_output_paths_are_checked_first(tmp_path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert "is a directory, not a file" in file_problem("--json", tmp_path)
    assert f"{blocker} is a file, not a directory" in file_problem("--json", blocker / "sub" / "r.json")
    assert "is an existing file, not a directory" in dir_problem("--out", blocker)
    assert file_problem("--json", tmp_path / "new" / "deeper" / "r.json") is None  # created when written
    assert dir_problem("--out", tmp_path / "new") is None
    assert plugin_problem("stereo", "builtin") is None
    assert "--planner: plugin nope_module:P" in plugin_problem("planner", "nope_module:P")
    junit = tmp_path / "j.xml"
    r = CliRunner().invoke(app, ["bench", "dimes", "--json", str(blocker / "r.json"), "--junit", str(junit)])
    assert r.exit_code == ExitStatus.BAD_INPUT and "--json" in r.stderr
    assert "--json" in _junit_cases(junit)["bench.dimes"].find("error").get("message")
    r = CliRunner().invoke(app, ["bench", "render", "--junit", str(blocker / "j.xml")])  # no JUnit can be written
    assert r.exit_code == ExitStatus.BAD_INPUT and "--junit" in r.stderr


def test_an_interrupted_benchmark_says_interrupted_in_its_junit(tmp_path, monkeypatch) -> None:
    import rover_sim.bench.dimes as dimes

    def interrupted(*_a, **_kw):  # noqa: ANN202
        raise KeyboardInterrupt

    monkeypatch.setattr(dimes, "bench_dimes", interrupted)
    junit = tmp_path / "dimes.xml"
    r = CliRunner().invoke(app, ["bench", "dimes", "--junit", str(junit)])
    assert r.exit_code == ExitStatus.SIGINT
    error = _junit_cases(junit)["bench.dimes"].find("error")
    assert error is not None and error.get("message") == "run did not complete: interrupted (Ctrl-C)"


def test_failing_console_rows_carry_their_reason() -> None:
    assert acceptance.pass_cell(False, "VO error 4.0 % > 3.0 %") == "NO: VO error 4.0 % > 3.0 %"
    stopped = acceptance.Verdict(error="run did not complete: interrupted (SIGTERM)")
    assert stopped.cell() == "NO: run did not complete: interrupted (SIGTERM)"
