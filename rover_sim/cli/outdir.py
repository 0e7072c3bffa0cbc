"""Output paths of every command, checked before any work: :func:`check_outputs` refuses an ``--out``, ``--json``,
``--junit`` or ``--png`` that cannot be written (a read-only place, a file where a directory is needed, ...), and
:func:`prepare_out_dir` refuses a non-empty ``--out`` directory unless ``--overwrite``, which clears its contents
(never ``/``, the home directory, the repository, the working directory or anything above them, nor any tree
holding a ``.git``)."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from rover_sim.errors import RoverSimError

REPO_ROOT = Path(__file__).resolve().parents[2]


class OutDirRefused(RoverSimError):
    """``--out`` names a file, a non-empty directory without ``--overwrite``, or a directory too precious to clear."""


class OutputNotWritable(RoverSimError):
    """An output option names a place that cannot be written; the message names the option and the path."""


def _nearest_existing(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def write_problem(path: Path, kind: str = "file") -> str | None:
    """Why ``path`` cannot be written as a ``kind`` ("file" or "dir", created with its parents if missing), or
    None. A probe file is created and removed in the directory that would receive it."""
    path = Path(path)
    if kind == "file" and path.is_dir():
        return "is a directory, not a file"
    if kind == "dir" and path.exists() and not path.is_dir():
        return "is an existing file, not a directory"
    if kind == "file" and path.is_file() and not os.access(path, os.W_OK):
        return "the file is not writable"
    base = _nearest_existing(path if kind == "dir" else path.parent)
    if not base.is_dir():
        return f"{base} is a file, not a directory"
    try:
        fd, probe = tempfile.mkstemp(prefix=".rover-sim-write-check-", dir=base)
    except OSError as e:
        return f"cannot write in {base} ({e.strerror or e})"
    os.close(fd)
    os.unlink(probe)
    return None


def check_outputs(*outputs: tuple[str, Path | str | None, str]) -> None:
    """Raise :class:`OutputNotWritable` for the first ``(option, path, kind)`` whose path cannot be written
    (``path`` None: the option was not given)."""
    for option, path, kind in outputs:
        if path is None or str(path) == "":
            continue
        problem = write_problem(Path(path), kind)
        if problem:
            raise OutputNotWritable(f"{option} {path}: {problem}")


def outputs_or_exit(*outputs: tuple[str, Path | str | None, str]) -> None:
    """:func:`check_outputs` for a command: an unwritable output is one line on stderr and exit 2."""
    from rover_sim.cli.status import fail

    try:
        check_outputs(*outputs)
    except OutputNotWritable as e:
        raise fail(e) from None


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
