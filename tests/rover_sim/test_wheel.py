"""The wheel works anywhere: built from this tree, installed in a fresh venv, run from outside the checkout.

The venv borrows this environment's installed dependencies (mujoco, numpy, ...) through a ``.pth`` file listing
its site-packages directories and its other ``sys.path`` entries outside the checkout; ``.pth`` files inside those
are not processed, so an editable install of rover-sim there stays invisible: ``rover_sim`` comes from the wheel
(checked), and no network is needed when this environment has the build requirement (``setuptools``).
"""

from __future__ import annotations

import os
import shutil
import site
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

import rover_sim
from rover_sim import resources

REPO = Path(__file__).resolve().parents[2]
SKIP_AT_TOP = {".git", ".venv", "venv", "runs", "build", "dist", ".pytest_cache", ".hypothesis", ".ruff_cache"}
pytestmark = pytest.mark.skipif(not (REPO / "setup.py").is_file(), reason="needs the source tree")


def _source_copy(dest: Path) -> Path:
    """The source tree without VCS data, venvs, outputs and build leftovers (a stale build/lib would leak in)."""

    def ignore(folder: str, names: list[str]) -> set[str]:
        top = SKIP_AT_TOP if Path(folder) == REPO else set()
        return {n for n in names if n in top or n == "__pycache__" or n.endswith((".egg-info", ".rrd"))}

    shutil.copytree(REPO, dest, ignore=ignore)
    return dest


def _build_isolation_needed() -> bool:
    """Whether this environment lacks the build requirement (then pip installs it from the index, as usual)."""
    from importlib.metadata import PackageNotFoundError, version

    from packaging.requirements import Requirement

    for text in tomllib.loads((REPO / "pyproject.toml").read_text())["build-system"]["requires"]:
        req = Requirement(text)
        try:
            if not req.specifier.contains(version(req.name), prereleases=True):
                return True
        except PackageNotFoundError:
            return True
    return False


def _clean_env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}


def _run(cmd: list, cwd: Path, timeout: float = 120.0) -> subprocess.CompletedProcess:
    res = subprocess.run(
        [str(c) for c in cmd], cwd=cwd, env=_clean_env(), capture_output=True, text=True, timeout=timeout
    )
    assert res.returncode == 0, f"{cmd} exited {res.returncode}\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    return res


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> dict[str, Path]:
    """Build the wheel from a copy of this tree, install it (no deps) into a fresh venv outside the checkout."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = _source_copy(tmp / "src")
    build = [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", tmp / "dist", src]
    if not _build_isolation_needed():
        build.insert(4, "--no-build-isolation")
    _run(build, tmp, timeout=300.0)
    (wheel,) = (tmp / "dist").glob("rover_sim-*.whl")

    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv], tmp)
    python = venv / "bin" / "python"
    purelib = Path(
        _run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], tmp).stdout.strip()
    )
    deps = [*site.getsitepackages(), sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    if site.ENABLE_USER_SITE:
        deps.append(site.getusersitepackages())
    deps += [p for p in sys.path if p and not Path(p).resolve().is_relative_to(REPO)]  # e.g. from other .pth files
    (purelib / "_rover_sim_test_deps.pth").write_text("\n".join(dict.fromkeys(d for d in deps if Path(d).is_dir())))
    _run([sys.executable, "-m", "pip", "--python", python, "install", "-q", "--no-deps", "--no-index", wheel], tmp)
    return {"tmp": tmp, "wheel": wheel, "python": python, "bin": python.parent, "site": purelib}


def test_source_tree_data_is_read_in_place():
    """A checkout (PYTHONPATH or editable install) reads models/, scenarios/, benchmarks/ where they are."""
    root = Path(rover_sim.__file__).resolve().parents[1]
    assert resources.source_checkout() == root
    assert resources.scenarios_dir() == root / "scenarios"
    assert (resources.models_dir() / "mer" / "scene.xml").is_file()
    assert resources.suite_baseline_path() == root / "benchmarks" / "suite_baseline.json"


def test_zipped_data_is_extracted_to_disk(tmp_path):
    archive = tmp_path / "data.zip"
    with zipfile.ZipFile(archive, "w") as z:
        z.writestr("models/mer/scene.xml", "<mujoco/>")
        z.writestr("models/mer/rover.xml", "<mujoco/>")
    folder = resources._on_disk(zipfile.Path(archive, "models/"))
    assert folder.is_dir() and folder.name == "models"
    assert (folder / "mer" / "scene.xml").read_text() == "<mujoco/>"


def test_wheel_ships_the_data_and_lists_the_catalogue(installed):
    shipped = {}
    with zipfile.ZipFile(installed["wheel"]) as z:
        for name in z.namelist():
            if name.startswith("rover_sim/_data/"):
                shipped[name.removeprefix("rover_sim/_data/")] = z.read(name)
    for folder in resources.DATA_FOLDERS:
        for f in (REPO / folder).rglob("*"):
            if f.is_file() and "__pycache__" not in f.parts and not f.name.startswith("."):
                rel = f.relative_to(REPO).as_posix()
                assert shipped.get(rel) == f.read_bytes(), f"{rel} missing from the wheel or different"

    cwd = installed["tmp"]  # outside the checkout: the source tree is not importable from here
    probe = (
        "import mujoco, rover_sim, rover_sim.resources as r\n"
        "from rover_sim.sim.assembly import SCENE_XML\n"
        "mujoco.MjSpec.from_file(str(SCENE_XML)).compile()\n"  # scene.xml includes rover.xml by relative path
        "print(rover_sim.__file__, r.source_checkout(), r.scenarios_dir(), r.suite_baseline_path().is_file())\n"
    )
    module, checkout, scen_dir, baseline = _run([installed["python"], "-c", probe], cwd).stdout.split()
    site_dir = installed["site"].resolve()
    assert Path(module).resolve().is_relative_to(site_dir), module
    assert checkout == "None" and baseline == "True"
    assert Path(scen_dir).resolve() == site_dir / "rover_sim" / "_data" / "scenarios"

    out = _run([installed["bin"] / "rover-sim", "scenarios"], cwd).stdout
    rows = [line.split(None, 2) for line in out.splitlines()]
    assert [r[0] for r in rows] == sorted(p.stem for p in (REPO / "scenarios").glob("*.toml"))
    assert len(rows) >= 13
    assert all(r[1] in ("fast", "-") and len(r) == 3 for r in rows), out
    assert ("wopmay", "fast") in {(r[0], r[1]) for r in rows}

    # the packaged baseline is read-only data: updating it needs an explicit file (checked before any run)
    res = subprocess.run(
        [installed["bin"] / "rover-sim", "bench", "suite", "--update-baseline"],
        cwd=cwd,
        env=_clean_env(),
        capture_output=True,
        text=True,
        timeout=120.0,
    )
    assert res.returncode == 2 and "--baseline PATH" in res.stderr, res.stderr


@pytest.mark.slow
def test_wheel_runs_a_scenario_by_name(installed):
    out = installed["tmp"] / "run"
    res = _run(
        [installed["bin"] / "rover-sim", "run", "msstb_rock_course", "--out", out, "--no-progress"],
        installed["tmp"],
        timeout=900.0,
    )
    assert "msstb_rock_course: PASS" in res.stdout
    assert (out / "metrics.json").is_file() and (out / "recording.rrd").is_file()


def test_wheel_ships_the_example_vo(installed):
    """The example VO the CLI help names is a module of the wheel (``examples/`` at the top of a checkout is not
    packaged, so it must live inside ``rover_sim``)."""
    from rover_sim.examples import EXAMPLE_VO

    module = EXAMPLE_VO.split(":")[0]
    with zipfile.ZipFile(installed["wheel"]) as z:
        assert f"{module.replace('.', '/')}.py" in z.namelist()


@pytest.mark.slow
def test_wheel_loads_the_example_vo_by_its_documented_name(installed):
    """From the installed wheel, outside the checkout: the name in ``bench vo --help`` loads the example VO."""
    from rover_sim.examples import EXAMPLE_VO

    probe = (
        "from rover_sim.runtime.plugins import resolve\n"
        f"cls = resolve({EXAMPLE_VO!r})\n"
        "import nav.protocols, sys\n"
        "print(sys.modules[cls.__module__].__file__, isinstance(cls(), nav.protocols.VisualOdometer))\n"
    )
    where, is_vo = _run([installed["python"], "-c", probe], installed["tmp"]).stdout.split()
    assert Path(where).resolve().is_relative_to(installed["site"].resolve()) and is_vo == "True"
    help_text = _run([installed["bin"] / "rover-sim", "bench", "vo", "--help"], installed["tmp"]).stdout
    assert EXAMPLE_VO in " ".join(help_text.replace("│", " ").split())
