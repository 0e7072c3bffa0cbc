"""Where the shipped data lives: the MER model, the scenario catalogue and the suite baseline.

Every path to packaged data goes through this module, so the source tree and an installed wheel resolve alike.
"""

from __future__ import annotations

from pathlib import Path

_ROOT = Path(__file__).resolve().parent.parent


def models_dir() -> Path:
    """The folder holding ``mer/rover.xml`` and ``mer/scene.xml``."""
    return _ROOT / "models"


def scenarios_dir() -> Path:
    """The scenario catalogue (``*.toml``)."""
    return _ROOT / "scenarios"


def suite_baseline_path() -> Path:
    """The committed ``bench suite`` baseline."""
    return _ROOT / "benchmarks" / "suite_baseline.json"
