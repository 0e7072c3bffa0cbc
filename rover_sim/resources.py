"""Where the shipped data lives: the MER model, the scenario catalogue and the suite baseline.

Every path to packaged data goes through this module, so the source tree and an installed wheel resolve alike:

* in a source checkout (``PYTHONPATH=.``, or the editable install ``pip install -e .``) the top-level folders
  ``models/``, ``scenarios/`` and ``benchmarks/`` are read in place, so edits to them are seen at once;
* in an installed wheel they are the package data ``rover_sim/_data/<folder>/`` (``setup.py`` maps the source
  folders there), found through ``importlib.resources``.

MuJoCo opens ``scene.xml`` by file name and resolves its ``include`` relative to it, so every folder handed out
here is a real directory on disk (data inside a zip archive is extracted once to a temporary directory).
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
from functools import cache
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path

DATA_FOLDERS = ("models", "scenarios", "benchmarks")
_ROOT = Path(__file__).resolve().parent.parent  # the source tree's root, when running from one


def source_checkout() -> Path | None:
    """The root of the source tree rover_sim runs from (plain checkout or editable install); None when installed."""
    if (_ROOT / "pyproject.toml").is_file() and all((_ROOT / name).is_dir() for name in DATA_FOLDERS):
        return _ROOT
    return None


@cache
def data_dir(folder: str) -> Path:
    """One of ``DATA_FOLDERS`` as a directory on disk: the source folder in a checkout, else the packaged copy."""
    if folder not in DATA_FOLDERS:
        raise ValueError(f"unknown data folder {folder!r} (one of {', '.join(DATA_FOLDERS)})")
    root = source_checkout()
    if root is not None:
        return root / folder
    return _on_disk(resources.files("rover_sim").joinpath("_data", folder))


def _on_disk(node: Traversable) -> Path:
    """``node`` itself when it is a filesystem path, else a copy of its tree in a temporary directory."""
    if isinstance(node, Path):
        return node
    tmp = Path(tempfile.mkdtemp(prefix="rover_sim_data_"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    _copy_tree(node, tmp / node.name)
    return tmp / node.name


def _copy_tree(node: Traversable, dest: Path) -> None:
    if node.is_file():
        dest.write_bytes(node.read_bytes())
        return
    dest.mkdir(parents=True, exist_ok=True)
    for child in node.iterdir():
        _copy_tree(child, dest / child.name)


def models_dir() -> Path:
    """The folder holding ``mer/rover.xml`` and ``mer/scene.xml``."""
    return data_dir("models")


def scenarios_dir() -> Path:
    """The scenario catalogue (``*.toml``)."""
    return data_dir("scenarios")


def suite_baseline_path() -> Path:
    """The ``bench suite`` baseline: committed in ``benchmarks/`` of the source tree, read-only data when installed."""
    return data_dir("benchmarks") / "suite_baseline.json"
