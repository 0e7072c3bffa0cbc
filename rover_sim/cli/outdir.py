"""``--out`` for ``rover-sim run``: refuse a non-empty directory unless ``--overwrite``, which clears its contents
(never ``/``, the home directory, the repository, the working directory or anything above them, nor any tree
holding a ``.git``)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from rover_sim.errors import RoverSimError

REPO_ROOT = Path(__file__).resolve().parents[2]


class OutDirRefused(RoverSimError):
    """``--out`` names a file, a non-empty directory without ``--overwrite``, or a directory too precious to clear."""


def _protected(d: Path) -> str | None:
    """Why ``d`` (resolved) may not be cleared, or None."""
    home = Path.home().resolve()
    cwd = Path.cwd().resolve()
    if d == Path(d.anchor):
        return "it is the filesystem root"
    for name, p in (
        ("your home directory", home),
        ("the rover-sim repository", REPO_ROOT),
        ("the working directory", cwd),
    ):
        if d == p or d in p.parents:
            return f"it is {name}" if d == p else f"it contains {name}"
    for root, dirs, files in os.walk(d):  # we are about to delete all of it: looking first costs the same
        if ".git" in dirs or ".git" in files:
            return f"{root} holds a .git (a repository)"
        dirs[:] = [x for x in dirs if not os.path.islink(os.path.join(root, x))]
    return None


def prepare_out_dir(out: Path, overwrite: bool) -> None:
    """Check ``out`` before a run; with ``overwrite`` clear a non-empty one (its contents only)."""
    if out.exists() and not out.is_dir():
        raise OutDirRefused(f"--out {out}: is an existing file, not a directory")
    if not out.is_dir() or not any(out.iterdir()):
        return
    if not overwrite:
        raise OutDirRefused(f"--out {out}: directory is not empty (add --overwrite to replace its contents)")
    d = out.resolve()
    why = _protected(d)
    if why:
        raise OutDirRefused(f"--out {out}: refusing to clear it: {why}")
    for child in d.iterdir():
        if child.is_symlink() or not child.is_dir():
            child.unlink()  # a symlink is removed, never followed
        else:
            shutil.rmtree(child)
