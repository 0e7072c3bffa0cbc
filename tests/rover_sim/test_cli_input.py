"""Bad input names what the user typed: a mistyped scenario gets the closest names, an invalid ``--seed``/``--set``
value blames the flag (with the allowed range), not the scenario file inside the installed package; and
``rover-sim scenarios`` prints each description's first sentence whole."""

from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from rover_sim.cli.main import app
from rover_sim.cli.status import ExitStatus
from rover_sim.scenario.loading import catalogue, load_scenario


def one_line_error(args: list[str]) -> str:
    r = CliRunner().invoke(app, args)
    assert r.exit_code == ExitStatus.BAD_INPUT, (r.exit_code, r.output, r.exception)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in r.output, r.output
    return lines[0]


@pytest.mark.parametrize(
    ("typed", "suggested"),
    [
        ("wopmay_typo", "'wopmay'"),
        ("wopmy", "'wopmay'"),
        ("msstb", "'msstb_rock_course'"),
        ("purgatory_ripple_v0", "'purgatory_ripple_vo'"),
    ],  # fmt: skip
)
def test_a_mistyped_scenario_gets_did_you_mean(tmp_path, typed, suggested):
    line = one_line_error(["run", typed, "--out", str(tmp_path / "o")])
    assert f"no scenario named '{typed}' (did you mean " in line and suggested in line, line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("args", "flag", "words"),
    [
        (["--seed", "-1"], "--seed -1", ["seed", ">= 0", "ge 0"]),
        (["--set", "nav.vo_step_m=9"], "--set nav.vo_step_m=9", ["nav.vo_step_m", "le 0.75"]),
        (["--set", "commands.0.distance_m=abc"], "--set commands.0.distance_m=abc", ["valid number"]),
        (["--set", "nosuch.key=1"], "--set nosuch.key=1", ["nosuch", "Extra inputs"]),
    ],
)
def test_flag_errors_blame_the_flag_not_the_file(tmp_path, args, flag, words):
    line = one_line_error(["run", "wopmay", "--out", str(tmp_path / "o"), *args])
    assert line.startswith(f"error: {flag}: "), line
    assert ".toml" not in line, line  # not the scenario file (inside the installed package for a wheel user)
    for w in words:
        assert w in line.replace("greater than or equal to", ">="), line


def test_errors_of_the_file_itself_still_name_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\nseed = -3\ncommands = [{ type = "drive", distance_m = 1.0 }]\n')
    line = one_line_error(["run", str(bad), "--out", str(tmp_path / "o"), "--set", "nav.vo_step_m=0.5"])
    assert line.startswith(f"error: {bad}: field 'seed'"), line


def test_sweep_grid_errors_blame_the_grid(tmp_path):
    line = one_line_error(["sweep", "wopmay", "--grid", "nav.vo_step_m=0.3,9", "--out", str(tmp_path / "s")])
    assert line.startswith("error: --grid nav.vo_step_m=9: "), line


def test_scenarios_prints_each_first_sentence_whole():
    r = CliRunner().invoke(app, ["scenarios"])
    assert r.exit_code == 0, r.output
    rows = {line.split(None, 2)[0]: line.split(None, 2)[2] for line in r.stdout.splitlines()}
    assert sorted(rows) == catalogue()
    for name, text in rows.items():
        description = " ".join(load_scenario(name).description.split())
        assert description.startswith(text), name
        assert text == description or re.search(r"[.!?]$", text), f"{name}: cut mid-sentence: {text!r}"
    assert rows["flat_benign"].endswith("(Ali et al. 2005; REFERENCE section 3.1).")  # not cut at "et al."


def test_bench_suite_unknown_scenario_is_bad_input_before_any_run(tmp_path):
    r = CliRunner().invoke(app, ["bench", "suite", "--scenario", "wopmay", "--scenario", "nosuch", "--seeds", "1",
                                 "--json", str(tmp_path / "s.json")])  # fmt: skip
    assert r.exit_code == ExitStatus.BAD_INPUT, r.output
    assert "--scenario" in r.output and "nosuch" in r.output and "wopmay" in r.output
    assert not (tmp_path / "s.json").exists()
