"""What every command checks before any work: its output paths and plugin specs (fail fast and say why).

:func:`preflight` is the first call of every command that writes files or loads plugins. A path that cannot be
written (a directory where a file is wanted, a file in the way, a read-only place) or a plugin that does not load
(``--vo``, ``--stereo``, ``--planner``) stops the command at once: one line on stderr naming the option, exit status
2, and, when ``--junit P`` was given and P can be written, a JUnit file at P with one error case saying why.
Nothing is created here; the command creates its directories when it writes.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

from rover_sim.cli.outdir import write_problem
from rover_sim.cli.status import ExitStatus, fail
from rover_sim.errors import RoverSimError

PLUGIN_KINDS = ("vo", "stereo", "planner")


def file_problem(option: str, path: Path | str | None) -> str | None:
    """Why ``option``'s file ``path`` cannot be written (None: it can, or no path was given)."""
    if path is None or str(path) == "":
        return None
    problem = write_problem(Path(path), "file")
    return None if problem is None else f"{option} {path}: {problem}"


def dir_problem(option: str, path: Path | str | None) -> str | None:
    """Why ``option``'s output directory ``path`` cannot be written (None: it can, or no path was given)."""
    if path is None or str(path) == "":
        return None
    problem = write_problem(Path(path), "dir")
    return None if problem is None else f"{option} {path}: {problem}"


def plugin_problem(kind: str, spec: str | None) -> str | None:
    """Why the ``kind`` ("vo", "stereo", "planner") implementation ``spec`` does not load (None: it does)."""
    if not spec or spec == "builtin":
        return None
    from nav.gestalt import GestaltParams
    from nav.stereo import StereoParams
    from nav.vo import VoParams
    from rover_sim.runtime.plugins import instantiate

    params = {"vo": VoParams, "stereo": StereoParams, "planner": GestaltParams}[kind]()
    try:
        instantiate(kind, spec, params)
    except RoverSimError as err:
        return f"--{kind}: {err}"
    return None


def preflight(
    suite: str,
    junit: Path | str | None = None,
    *,
    files: Mapping[str, Path | str | None] | None = None,
    dirs: Mapping[str, Path | str | None] | None = None,
    plugins: Mapping[str, Iterable[str] | str | None] | None = None,
) -> None:
    """Check ``--junit``, the output ``files`` and ``dirs`` (option -> path) and the ``plugins`` (kind -> spec or
    specs) before ``suite`` (the command's name) does any work; on a problem, exit 2 as the module says."""
    problems = [file_problem("--junit", junit)]
    problems += [file_problem(opt, p) for opt, p in (files or {}).items()]
    problems += [dir_problem(opt, p) for opt, p in (dirs or {}).items()]
    for kind, specs in (plugins or {}).items():
        for spec in [specs] if isinstance(specs, str) or specs is None else specs:
            problems.append(plugin_problem(kind, spec))
    found = [p for p in problems if p]
    if not found:
        return
    message = "; ".join(found)
    if junit is not None and problems[0] is None:
        from rover_sim.io.junit import error_case, write_junit

        write_junit(junit, suite, [error_case(suite, f"bad input: {message}")])
    raise fail(message, ExitStatus.BAD_INPUT)
