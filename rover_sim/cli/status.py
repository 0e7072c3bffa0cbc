"""Exit statuses of ``rover-sim run`` and every ``rover-sim bench`` command, in one place (docs/cli.md).

| status | meaning |
|---:|---|
| 0 | every criterion met |
| 1 | a criterion failed (the run or benchmark completed) |
| 2 | bad input: an invalid scenario or ``--set``, a bad option, a plugin that does not load, ``--out`` refused |
| 3 | a run error: physics diverged, a plugin raised or answered outside its protocol |
| 130 | interrupted by Ctrl-C (SIGINT); partial outputs are written |
| 143 | stopped by SIGTERM; partial outputs are written |
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from enum import IntEnum

import typer

from rover_sim import interrupts
from rover_sim.errors import PluginError, RoverSimError, Terminated

RUN_DID_NOT_COMPLETE = "run did not complete"
# a PluginError raised here is the user's input (a plugin that cannot be loaded), not a run error
PLUGIN_SETUP = ("import", "name", "constructor", "protocol")


class ExitStatus(IntEnum):
    OK = 0
    FAILED = 1
    BAD_INPUT = 2
    RUN_ERROR = 3
    SIGINT = 130
    SIGTERM = 143


_RANK = {ExitStatus.OK: 0, ExitStatus.FAILED: 1, ExitStatus.RUN_ERROR: 2, ExitStatus.BAD_INPUT: 3,
         ExitStatus.SIGINT: 4, ExitStatus.SIGTERM: 5}  # fmt: skip


def of_interrupt(exc: BaseException) -> ExitStatus:
    return ExitStatus.SIGTERM if isinstance(exc, Terminated) else ExitStatus.SIGINT


def of_reason(passed: bool, reason: str) -> ExitStatus:
    """The status of one scenario run from its ``metrics.passed`` and ``metrics.reason``."""
    if passed:
        return ExitStatus.OK
    if not reason.startswith(RUN_DID_NOT_COMPLETE):
        return ExitStatus.FAILED
    if interrupts.INTERRUPTED in reason:
        return ExitStatus.SIGTERM if f"({interrupts.SIGTERM})" in reason else ExitStatus.SIGINT
    return ExitStatus.RUN_ERROR


def of_error(err: RoverSimError) -> ExitStatus:
    if isinstance(err, PluginError) and err.where not in PLUGIN_SETUP:
        return ExitStatus.RUN_ERROR
    from rover_sim.errors import PhysicsDiverged

    return ExitStatus.RUN_ERROR if isinstance(err, PhysicsDiverged) else ExitStatus.BAD_INPUT


def worst(statuses: Iterable[ExitStatus | int]) -> ExitStatus:
    """The most severe status: interrupted > bad input > run error > criterion failed > ok."""
    return max((ExitStatus(s) for s in statuses), key=_RANK.__getitem__, default=ExitStatus.OK)


def fail(message: object, status: ExitStatus = ExitStatus.BAD_INPUT) -> typer.Exit:
    """Print ``error: message`` (one line, red, stderr) and return the Exit to raise."""
    text = " ".join(str(message).split("\n"))
    typer.secho(f"error: {text}", fg=typer.colors.RED, err=True)
    return typer.Exit(code=int(status))


@contextmanager
def guarded(junit: str | None = None, suite: str = "") -> Iterator[None]:
    """Around a command's body: a RoverSimError is one line on stderr (status 2 or 3), Ctrl-C exits 130 and
    SIGTERM 143 with one line saying so (no traceback). SIGTERM raises :class:`Terminated` meanwhile. With
    ``junit``, the JUnit file then holds one error case saying why (e.g. "interrupted (Ctrl-C)")."""
    try:
        with interrupts.sigterm_raises():
            yield
    except RoverSimError as e:
        status = of_error(e)
        _junit_error(junit, suite, f"{'bad input' if status == ExitStatus.BAD_INPUT else RUN_DID_NOT_COMPLETE}: {e}")
        raise fail(e, status) from None
    except KeyboardInterrupt as e:
        _junit_error(junit, suite, f"{RUN_DID_NOT_COMPLETE}: {interrupts.describe(e)}")
        typer.secho(f"{interrupts.describe(e)}: stopped", fg=typer.colors.RED, err=True)
        raise typer.Exit(code=int(of_interrupt(e))) from None


def _junit_error(junit: str | None, suite: str, message: str) -> None:
    if junit:
        from rover_sim.io.junit import error_case, write_junit

        try:
            write_junit(junit, suite or "rover-sim", [error_case(suite or "rover-sim", message)])
        except OSError:  # the path was checked first (cli/preflight.py); a vanished directory is not worth a traceback
            pass


def exit_with(status: ExitStatus | int) -> None:
    """Raise the Exit for a non-zero status."""
    if int(status) != 0:
        raise typer.Exit(code=int(status))


def of_cases(cases: Iterable) -> ExitStatus:  # Iterable[rover_sim.io.junit.Case]
    """A benchmark's status from its cases: an error is a run error (or the interrupt it names), a failure 1."""
    out = []
    for c in cases:
        if c.error is not None:
            reason = c.error if c.error.startswith(RUN_DID_NOT_COMPLETE) else f"{RUN_DID_NOT_COMPLETE}: {c.error}"
            out.append(of_reason(False, reason))
        elif c.failure is not None:
            out.append(ExitStatus.FAILED)
    return worst(out)


def finish(junit: str | None, suite: str, cases: list, extra: Iterable[ExitStatus] = ()) -> None:
    """Write ``--junit`` (if given) and exit with the worst status of ``cases`` and ``extra``."""
    from rover_sim.io.junit import write_junit

    write_junit(junit, suite, cases)
    exit_with(worst([of_cases(cases), *extra]))
