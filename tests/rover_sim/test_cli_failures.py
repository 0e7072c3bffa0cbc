"""Clean failure modes of the CLI: exit statuses, SIGTERM/Ctrl-C mid-run and during setup, one-line
errors for bad input, --out safety, zero-distance runs, JUnit output and the user's own suite baseline."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from tiny_scenario import TINY_TOML as TINY_DRIVE_TOML
from typer.testing import CliRunner

from rover_sim.cli.main import app
from rover_sim.cli.outdir import OutDirRefused, prepare_out_dir
from rover_sim.cli.status import ExitStatus, of_reason, worst
from rover_sim.errors import ConfigError
from rover_sim.io.junit import Case, write_junit
from rover_sim.runtime.run import run_scenario
from rover_sim.scenario.loading import scenario_from_dict

ROOT = Path(__file__).resolve().parents[2]
RERUN = Path(sys.executable).with_name("rerun")

TINY_TOML = (
    TINY_DRIVE_TOML
    + """[pass]
max_vo_error_pct = 3.0
"""
)

FLAT = {
    "name": "flat",
    "seed": 1,
    "terrain": {"size_m": [6, 6], "cell_size_m": 0.05, "rocks": {"cover_fraction": 0.0}},
    "nav": {"vo": False},
    "commands": [{"type": "drive", "distance_m": 0.0}],
    "pass": {"max_dr_error_pct": 5.0},
}


@pytest.fixture
def tiny(tmp_path) -> Path:
    p = tmp_path / "tiny.toml"
    p.write_text(TINY_TOML)
    return p


def _start(args: list[str], **kw) -> subprocess.Popen:
    env = os.environ | {"MUJOCO_GL": "egl", "PYTHONPATH": str(ROOT), "COLUMNS": "200"}
    return subprocess.Popen(
        [sys.executable, "-m", "rover_sim.cli.main", *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        # a shell's background job ignores SIGINT, and Python then keeps ignoring it: restore the default
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        **kw,
    )


def _wait_for(pred, proc: subprocess.Popen, timeout_s: float, what: str) -> None:
    t0 = time.monotonic()
    while not pred():
        if proc.poll() is not None:
            raise AssertionError(f"exited ({proc.returncode}) before {what}: {proc.stderr.read().decode()[-2000:]}")
        if time.monotonic() - t0 > timeout_s:
            proc.kill()
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def _verify_rrd(path: Path) -> None:
    if not RERUN.exists():
        pytest.skip("no rerun CLI beside this python")
    r = subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr


def test_sigterm_mid_run_stops_cleanly(tiny, tmp_path):
    out, junit = tmp_path / "out", tmp_path / "junit.xml"
    proc = _start(["run", str(tiny), "--out", str(out), "--junit", str(junit), "--set", "commands.0.distance_m=5"])
    seen: list[str] = []

    def read_stderr() -> None:  # progress lines (stderr is a pipe): "tiny: N sim-s, M s" once the loop runs
        while chunk := proc.stderr.read1(4096):
            seen.append(chunk.decode(errors="replace"))

    reader = threading.Thread(target=read_stderr, daemon=True)
    reader.start()

    def looping() -> bool:
        return any(int(n) >= 6 for n in re.findall(r"(\d+) sim-s", "".join(seen)))

    _wait_for(looping, proc, 120, "the mission loop")
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == ExitStatus.SIGTERM == 143
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["reason"] == "run did not complete: interrupted (SIGTERM)"
    assert metrics["distance_m"] > 0
    assert "interrupted (SIGTERM)" in (out / "events.log").read_text()
    assert (out / "trajectories" / "truth.tum").stat().st_size > 0
    _verify_rrd(out / "recording.rrd")
    err = ET.parse(junit).getroot().find("testsuite/testcase/error")
    assert err is not None and "SIGTERM" in err.get("message")


def test_ctrl_c_during_setup_writes_what_it_can(tiny, tmp_path):
    out = tmp_path / "out"
    # a larger terrain: building the world takes seconds; the recording file exists before it starts
    proc = _start(["run", str(tiny), "--out", str(out), "--set", "terrain.size_m=[24,24]", "--no-progress"])
    _wait_for((out / "recording.rrd").exists, proc, 120, "the recorder")
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=60) == ExitStatus.SIGINT == 130
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["reason"] == "run did not complete: interrupted during setup (Ctrl-C)"
    assert json.loads((out / "scenario.json").read_text())["name"] == "tiny"
    assert "interrupted during setup" in (out / "events.log").read_text()
    _verify_rrd(out / "recording.rrd")


def _one_line_error(args: list[str]) -> str:
    r = CliRunner().invoke(app, args)
    assert r.exit_code == ExitStatus.BAD_INPUT, (r.exit_code, r.output, r.exception)
    assert "Traceback" not in r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert "Traceback" not in r.stderr
    return lines[0]


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--set", "commands.5.x=1"], "index 5 out of range: 'commands' has 1 item"),
        (["--set", "commands.x.y=1"], "'x' is not an index"),
        (["--set", "nav.vo_step_m=9"], "nav.vo_step_m"),
        (["--vo", "no_such_module:Nope", "--no-progress"], "cannot import module"),
    ],
)
def test_run_bad_input_is_one_line(tiny, tmp_path, args, expected):
    assert expected in _one_line_error(["run", str(tiny), "--out", str(tmp_path / "o"), *args])
    if args[0] == "--set":
        assert not (tmp_path / "o").exists()  # rejected before anything was written


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--pair", "foo"], "choose from navcam, hazcam_front, hazcam_rear"),
        (["--resolution", "0"], "allowed 16..2048"),
        (["--resolution", "100000"], "allowed 16..2048"),
    ],
)
def test_render_bad_input_is_one_line(tiny, tmp_path, args, expected):
    assert expected in _one_line_error(["render", str(tiny), "--out", str(tmp_path / "r"), *args])


def test_out_refusals(tiny, tmp_path):
    f = tmp_path / "afile"
    f.write_text("x")
    assert "existing file" in _one_line_error(["run", str(tiny), "--out", str(f)])
    full = tmp_path / "full"
    (full / "sub").mkdir(parents=True)
    assert "not empty" in _one_line_error(["run", str(tiny), "--out", str(full)])
    (full / "sub" / ".git").mkdir()
    assert "holds a .git" in _one_line_error(["run", str(tiny), "--out", str(full), "--overwrite"])
    for precious in ("/", str(Path.home()), str(ROOT)):
        with pytest.raises(OutDirRefused, match="refusing to clear"):
            prepare_out_dir(Path(precious), overwrite=True)


def test_overwrite_clears_contents_only(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "keep.txt").write_text("keep")
    out = tmp_path / "out"
    (out / "plots").mkdir(parents=True)
    (out / "metrics.json").write_text("{}")
    (out / "link").symlink_to(outside, target_is_directory=True)
    prepare_out_dir(out, overwrite=True)
    assert out.is_dir() and not any(out.iterdir())
    assert (outside / "keep.txt").read_text() == "keep"  # a symlink is removed, never followed


def test_bench_bad_input_is_one_line(tmp_path):
    assert "--case 'nope'" in _one_line_error(["bench", "vo", "--case", "nope"])
    assert "no such baseline file" in _one_line_error(["bench", "suite", "--baseline", str(tmp_path / "none.json")])
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2")
    assert "not valid JSON" in _one_line_error(["bench", "suite", "--baseline", str(bad)])


@pytest.mark.parametrize(
    "override",
    [[], ['commands=[{type = "mast", pan_deg = 20, tilt_deg = -30}]', "pass={}"]],
    ids=["drive_0m", "mast_only"],
)
def test_zero_distance_runs_complete_with_sensible_metrics(tmp_path, override):
    m = run_scenario(scenario_from_dict(FLAT, overrides=override), tmp_path, record=False)
    assert m.distance_m < 0.1
    assert m.dr_error_pct is None and m.vo_error_pct is None  # a percentage of ~0 m is not a measurement
    assert m.dr_error_m is not None and m.dr_error_m < 0.05
    assert (tmp_path / "metrics.json").is_file() and (tmp_path / "plots" / "paths.png").is_file()
    if override:
        assert m.passed, m.reason
    else:
        assert not m.passed and "DR error not measured" in m.reason


def test_exit_status_mapping():
    assert of_reason(True, "all criteria met") == ExitStatus.OK
    assert of_reason(False, "VO error 4.0 % > 3.0 %") == ExitStatus.FAILED
    assert of_reason(False, "run did not complete: physics diverged at t=1.000 s: NaN") == ExitStatus.RUN_ERROR
    assert of_reason(False, "run did not complete: plugin x: step(): raised ValueError") == ExitStatus.RUN_ERROR
    assert of_reason(False, "run did not complete: interrupted (Ctrl-C)") == ExitStatus.SIGINT
    assert of_reason(False, "run did not complete: interrupted during setup (SIGTERM)") == ExitStatus.SIGTERM
    assert worst([ExitStatus.OK, ExitStatus.FAILED, ExitStatus.RUN_ERROR]) == ExitStatus.RUN_ERROR
    assert worst([ExitStatus.RUN_ERROR, ExitStatus.SIGTERM, ExitStatus.FAILED]) == ExitStatus.SIGTERM
    assert worst([]) == ExitStatus.OK


def test_set_index_errors_name_the_list():
    with pytest.raises(ConfigError, match=r"index 2 out of range: 'commands' has 1 item \(0..0\)"):
        scenario_from_dict(FLAT, overrides=["commands.2.distance_m=1"])
    with pytest.raises(ConfigError, match="'first' is not an index"):
        scenario_from_dict(FLAT, overrides=["commands.first.distance_m=1"])
    sc = scenario_from_dict(FLAT, overrides=["commands.0.distance_m=1.5"])
    assert sc.commands[0].distance_m == 1.5


def test_junit_writer(tmp_path):
    path = tmp_path / "j" / "out.xml"
    write_junit(
        path,
        "bench x",
        [
            Case("a", "bench.x"),
            Case("b", "bench.x", failure="VO error 4 % > 3 %"),
            Case("c", "bench.x", failure="run did not complete: boom", error="run did not complete: boom"),
        ],
    )
    root = ET.parse(path).getroot()
    suite = root.find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("3", "1", "1")
    cases = {c.get("name"): c for c in suite.findall("testcase")}
    assert cases["a"].find("failure") is None
    assert cases["b"].find("failure").get("message") == "VO error 4 % > 3 %"
    assert cases["c"].find("error") is not None
