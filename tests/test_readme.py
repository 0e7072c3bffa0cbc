"""The README's Python snippets run as written, each saved to a file and run as a script in a fresh interpreter (the
way a new user runs what they copy: a snippet that works pasted into an interactive interpreter can fail as a
script, e.g. a ``spawn`` worker re-importing a file that has no ``if __name__ == "__main__":`` guard)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
STARTS_PROCESSES = re.compile(r"AsyncVectorEnv|multiprocessing|ProcessPool|context=\"spawn\"|get_context\(")
MAIN_GUARD = re.compile(r"^if __name__ == [\"']__main__[\"']:", re.M)


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(), re.S)


def block_after(heading: str) -> str:
    text = README.read_text()
    section = text[text.index(heading) :]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def run_as_script(code: str, directory: Path, timeout_s: float = 900) -> subprocess.CompletedProcess:
    """Save ``code`` as ``directory/snippet.py`` and run it with this interpreter, from ``directory``."""
    script = directory / "snippet.py"
    script.write_text(code)
    env = os.environ | {"MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run(
        [sys.executable, str(script)], cwd=directory, env=env, capture_output=True, text=True, timeout=timeout_s
    )


RUN_BY_A_TEST = ("## Library guide", "## Gymnasium environment")


def test_every_python_snippet_is_run_by_a_test():
    """Each ``python`` block of the README is the one after a heading that a test below runs as a script."""
    assert sorted(python_blocks()) == sorted(block_after(h) for h in RUN_BY_A_TEST)


def test_snippets_that_start_processes_have_a_main_guard():
    """``spawn`` workers import the script again: without the guard each worker runs the whole script again."""
    for code in python_blocks():
        if STARTS_PROCESSES.search(code):
            assert MAIN_GUARD.search(code), f"a README snippet starts processes without a __main__ guard:\n{code}"


def test_run_as_script_catches_a_missing_main_guard(tmp_path):
    """The harness itself: the class of error the script run exists to catch does fail it."""
    body = "p = mp.get_context('spawn').Process(target=print, args=('worker ran',))\np.start()\np.join()\n"
    body += "sys.exit(p.exitcode)\n"
    head = "import multiprocessing as mp\nimport sys\n"
    r = run_as_script(head + body, tmp_path, timeout_s=120)
    assert r.returncode != 0 and "bootstrapping" in r.stderr, r.stderr
    guarded = head + "if __name__ == '__main__':\n" + "".join(f"    {line}\n" for line in body.splitlines())
    r = run_as_script(guarded, tmp_path, timeout_s=120)
    assert r.returncode == 0 and "worker ran" in r.stdout, r.stderr


def test_library_guide_runs_as_a_script(tmp_path):
    checks = (
        "\nimport json\n"
        "print('RESULT ' + json.dumps({'scenario': metrics.scenario, 'distance_m': metrics.distance_m, "
        "'dtype': pair.left_u8.dtype.name, 'truth_shape': list(truth.position_xyz_m.shape)}))\n"
    )
    r = run_as_script(block_after("## Library guide") + checks, tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    result = json.loads(r.stdout.split("RESULT ", 1)[1])
    assert result["scenario"] == "wopmay" and result["distance_m"] > 1.0
    assert result["dtype"] == "uint8" and result["truth_shape"] == [3]


@pytest.mark.slow
def test_gymnasium_snippet_runs_as_a_script(tmp_path):
    r = run_as_script(block_after("## Gymnasium environment"), tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "m closer, true position" in r.stdout
