"""The environment a benchmark ran in: the numbers a closed-loop drive depends on to the last bit.

The same code drives another route on another CPU or numeric library (a chaotic system amplifies last-bit
differences), so every benchmark JSON and every baseline records where it was measured.
"""

from __future__ import annotations

import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path

PACKAGES = ("rover-sim", "mujoco", "numpy", "scipy", "opencv-python-headless", "numba", "trimesh", "rerun-sdk")
ENV_VARS = ("OPENBLAS_CORETYPE", "MUJOCO_GL", "NAV_STEREO_ENGINE", "OMP_NUM_THREADS")


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _git_commit() -> str | None:
    from rover_sim.resources import source_checkout

    root = source_checkout()
    if root is None:
        return None
    try:
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                             text=True, timeout=5, check=True)  # fmt: skip
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5, check=True).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() + ("+dirty" if dirty else "")


def environment() -> dict:
    """Python, platform, CPU, package versions, the numeric environment variables and the source commit."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    from nav.stereo import sad_engine

    return {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpu": _cpu_model(),
        "cpus": os.cpu_count(),
        "packages": versions,
        "env": {k: os.environ.get(k) for k in ENV_VARS},
        "sad_engine": sad_engine(),
        "commit": _git_commit(),
    }
