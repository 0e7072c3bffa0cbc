"""What the CLI writes, and when: output paths checked before any work, a run that cannot start leaves nothing,
``export`` interrupted says so and exits 130/143, ``export --overwrite`` as ``run``'s, and progress that stays out of
logs (no carriage-return bars when stderr is not a terminal)."""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from tiny_scenario import TINY_TOML
from typer.testing import CliRunner

from rover_sim.cli.main import app
from rover_sim.cli.status import ExitStatus

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def tiny(tmp_path) -> Path:
    p = tmp_path / "tiny.toml"
    p.write_text(TINY_TOML)
    return p


def _start(args: list[str]) -> subprocess.Popen:
    env = os.environ | {"MUJOCO_GL": "egl", "PYTHONPATH": str(ROOT), "COLUMNS": "200"}
    return subprocess.Popen(
        [sys.executable, "-m", "rover_sim.cli.main", *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # a background job ignores SIGINT
    )


# ------------------------------------------------------------------------------------ output paths, checked first
def _unwritable(tmp_path: Path) -> list[Path]:
    """Places no process can write: below a regular file; and /sys (a kernel filesystem that takes no new files)
    when that holds here."""
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    places = [blocker / "sub"]
    probe = Path("/sys/rover_sim_test")
    try:
        probe.mkdir()
    except OSError:
        places.append(probe)
    else:
        probe.rmdir()
    return places


def _commands(tiny: Path, ok: Path, bad: Path) -> list[list[str]]:
    """Every command with an output option, each given one unwritable output (the rest as they come)."""
    png = ok / "l.png"
    cmds = [
        ["run", str(tiny), "--out", str(bad / "out")],
        ["run", str(tiny), "--out", str(ok / "run"), "--junit", str(bad / "j.xml")],
        ["export", str(tiny), "--out", str(bad / "out")],
        ["export", str(tiny), "--out", str(ok / "exp"), "--json", str(bad / "s.json")],
        ["render", str(tiny), "--out", str(bad / "out")],
        ["sweep", str(tiny), "--out", str(bad / "out")],
        ["stereo", str(png), str(png), "--out", str(bad / "d.npy")],
        ["bench", "slip", "--png", str(bad / "s.png")],
        ["bench", "traverse", "--out", str(bad / "out")],
        ["bench", "suite", "--fast", "--update-baseline", "--baseline", str(bad / "b.json")],
        ["bench", "suite", "--fast", "--png", str(bad / "box.png")],
        ["orbital", str(tiny), "--out", str(bad / "out")],
        ["bench", "globalloc", "--cache", str(bad / "cache")],
    ]
    for bench in (
        "slip",
        "render",
        "stereo",
        "autonav",
        "traverse",
        "dimes",
        "sweep",
        "rocks",
        "vo",
        "suite",
        "globalloc",
    ):
        cmds.append(["bench", bench, "--json", str(bad / "r.json")])
        cmds.append(["bench", bench, "--junit", str(bad / "j.xml")])
    return cmds


def test_unwritable_outputs_fail_in_one_line_before_any_work(tiny, tmp_path):
    ok = tmp_path / "ok"
    ok.mkdir()
    import cv2

    cv2.imwrite(str(ok / "l.png"), np.zeros((32, 32), np.uint8))
    for bad in _unwritable(tmp_path):
        for args in _commands(tiny, ok, bad):
            r = CliRunner().invoke(app, args)
            lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
            assert r.exit_code == ExitStatus.BAD_INPUT, (args, r.exit_code, r.output, r.exception)
            assert len(lines) == 1 and "Traceback" not in r.output, (args, r.output)
            option = next(a for a in args if a.startswith("--") and str(bad) in args[args.index(a) + 1])
            path = args[args.index(option) + 1]
            assert lines[0].startswith(f"error: {option} {path}: "), (args, lines[0])
    assert not any((ok / d).exists() for d in ("run", "exp"))  # nothing was started


def test_write_problem():
    from rover_sim.cli.outdir import write_problem

    assert write_problem(Path(__file__)) is None  # a writable file
    assert "is a directory" in write_problem(ROOT, "file")
    assert "not a directory" in write_problem(Path(__file__), "dir")
    assert "is a file, not a directory" in write_problem(Path(__file__) / "x.json")


# ------------------------------------------------------------------------------ a run that cannot start
def test_a_run_whose_plugin_does_not_load_leaves_no_files(tiny, tmp_path):
    out = tmp_path / "out"
    args = ["run", str(tiny), "--out", str(out), "--vo", "no_such_module:NoVO", "--no-progress"]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == ExitStatus.BAD_INPUT and "cannot import module 'no_such_module'" in r.stderr, r.output
    assert not out.exists()  # no recording.rrd, no directory: the identical command is accepted next time
    out.mkdir()
    r = CliRunner().invoke(app, args)
    assert r.exit_code == ExitStatus.BAD_INPUT and "not empty" not in r.stderr
    assert out.is_dir() and not any(out.iterdir())


# ----------------------------------------------------------------------------------------------- export
@pytest.mark.parametrize(
    ("sig", "status", "label"),
    [
        (signal.SIGTERM, ExitStatus.SIGTERM, "SIGTERM"),
        pytest.param(signal.SIGINT, ExitStatus.SIGINT, "Ctrl-C", marks=pytest.mark.slow),
    ],
)
def test_interrupted_export_says_so_and_keeps_the_frames(tiny, tmp_path, sig, status, label):
    out = tmp_path / "out"
    proc = _start(["export", str(tiny), "--out", str(out), "--set", "commands.0.distance_m=5", "--no-progress"])
    frames = out / "sequences" / "00" / "image_0"
    try:
        import time

        t0 = time.monotonic()
        while not (frames.is_dir() and len(list(frames.iterdir())) >= 2):  # the first pair and a VO step
            assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
            assert time.monotonic() - t0 < 300, "no frames written"
            time.sleep(0.05)
        proc.send_signal(sig)
        stdout, stderr = (b.decode() for b in proc.communicate(timeout=120))
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == status, stderr
    assert f"interrupted ({label})" in stderr and "cut short" in stderr, stderr
    assert stdout.strip() == "" and "Traceback" not in stderr  # not the normal success line
    n = len(np.loadtxt(out / "sequences" / "00" / "times.txt", ndmin=1))
    assert n >= 2 and len(list(frames.iterdir())) == n  # what was recorded is kept, consistently
    metrics = json.loads((out / "run" / "metrics.json").read_text())
    assert metrics["reason"] == f"run did not complete: interrupted ({label})"


def test_export_overwrite_clears_a_non_empty_out_like_run(tiny, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("from before")
    args = ["export", str(tiny), "--out", str(out), "--set", "commands.0.distance_m=0.0", "--no-progress"]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == ExitStatus.BAD_INPUT and "not empty (add --overwrite" in r.stderr, r.output
    assert (out / "old.txt").is_file()
    r = CliRunner().invoke(app, [*args, "--overwrite"])
    assert r.exit_code == 0, r.output
    assert not (out / "old.txt").exists() and (out / "sequences" / "00" / "times.txt").is_file()
    (out / "sub" / ".git").mkdir(parents=True)  # the same guard as run's --overwrite
    r = CliRunner().invoke(app, [*args, "--overwrite"])
    assert r.exit_code == ExitStatus.BAD_INPUT and "holds a .git" in r.stderr


# ---------------------------------------------------------------------------------------------- progress
def test_progress_writes_plain_lines_when_not_a_terminal(monkeypatch):
    from rover_sim.io import progress

    log = io.StringIO()  # not a terminal
    monkeypatch.setattr(progress, "LOG_INTERVAL_S", 0.0)
    bar = progress.SimProgress("tiny", stream=log)
    assert bar.bar is None
    for t in (0.5, 1.5, 2.5):
        bar.update(t)
    bar.close()
    text = log.getvalue()
    assert "\r" not in text and text.splitlines()[-1].startswith("tiny: 2 sim-s, ")


def test_progress_bar_on_a_terminal():
    from rover_sim.io import progress

    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    term = Tty()
    bar = progress.SimProgress("tiny", stream=term)
    bar.update(3.0)
    bar.close()
    assert "\r" in term.getvalue() and "3 sim-s" in term.getvalue()


def test_a_run_logged_to_a_file_has_no_carriage_returns(tiny, tmp_path):
    """The real command with stderr redirected to a file, as in CI: progress lines, never a redrawn bar."""
    log = tmp_path / "stderr.log"
    env = os.environ | {"MUJOCO_GL": "egl", "PYTHONPATH": str(ROOT)}
    args = [sys.executable, "-m", "rover_sim.cli.main", "run", str(tiny), "--out", str(tmp_path / "o"),
            "--set", "commands.0.distance_m=0.3", "--no-record"]  # fmt: skip
    with open(log, "w") as err:
        r = subprocess.run(args, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=err, timeout=600)
    raw = log.read_bytes()  # bytes: reading text would turn each carriage return into a newline
    assert r.returncode in (0, 1), raw[-2000:]
    assert b"\r" not in raw and b"tiny: " in raw and b"sim-s" in raw  # the closing progress line


def test_every_tqdm_bar_is_off_when_stderr_is_not_a_terminal():
    """Every tqdm bar in rover_sim is built with ``disable=None`` (tqdm then draws only on a terminal), except the
    one in rover_sim/io/progress.py, which is only built when the stream is a terminal."""
    import ast

    unguarded = []
    for path in sorted((ROOT / "rover_sim").rglob("*.py")):
        if path == ROOT / "rover_sim" / "io" / "progress.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) == "tqdm":
                disable = [k.value for k in node.keywords if k.arg == "disable"]
                if not (disable and isinstance(disable[0], ast.Constant) and disable[0].value is None):
                    unguarded.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not unguarded, "tqdm bars that draw into logs: " + ", ".join(unguarded)
