"""SIGTERM handled like Ctrl-C: within :func:`sigterm_raises` (and everywhere once the CLI called
:func:`install_sigterm_handler`) a SIGTERM raises :class:`~rover_sim.errors.Terminated`, a ``KeyboardInterrupt``,
in the main thread, so every ``except KeyboardInterrupt`` that keeps partial results works for both signals.

The texts here are what ``metrics.reason`` says after an interrupted run; :mod:`rover_sim.cli.status` maps them
to exit statuses (130 for Ctrl-C, 143 for SIGTERM).
"""

from __future__ import annotations

import multiprocessing
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from rover_sim.errors import Terminated

INTERRUPTED = "interrupted"
CTRL_C = "Ctrl-C"
SIGTERM = "SIGTERM"


def label(exc: BaseException) -> str:
    """``"SIGTERM"`` for :class:`Terminated`, ``"Ctrl-C"`` for any other ``KeyboardInterrupt``."""
    return SIGTERM if isinstance(exc, Terminated) else CTRL_C


def describe(exc: BaseException, during: str = "") -> str:
    """``interrupted (SIGTERM)`` or ``interrupted during setup (Ctrl-C)``: the text after "run did not complete: "."""
    return f"{INTERRUPTED}{' ' + during if during else ''} ({label(exc)})"


def raise_terminated(signum: int, frame: object) -> None:
    """The SIGTERM handler: raise :class:`Terminated` where the main thread is."""
    raise Terminated()


def _may_install() -> bool:
    """Only in the main thread of a top-level process, and only over the default action: a pool worker's SIGTERM
    belongs to its pool, and a handler the application installed itself is left alone."""
    return (
        threading.current_thread() is threading.main_thread()
        and multiprocessing.parent_process() is None
        and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    )


def install_sigterm_handler() -> bool:
    """Make SIGTERM raise :class:`Terminated` from now on (the CLI entry point); True if installed."""
    if not _may_install():
        return False
    signal.signal(signal.SIGTERM, raise_terminated)
    return True


@contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within the block SIGTERM raises :class:`Terminated` (see :func:`install_sigterm_handler` for when)."""
    if not _may_install():
        yield
        return
    previous = signal.signal(signal.SIGTERM, raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class Pending:
    """What :func:`deferred` caught: ``exc`` is the interrupt to raise later (None if no signal came)."""

    exc: KeyboardInterrupt | None = None


@contextmanager
def deferred() -> Iterator[Pending]:
    """Hold Ctrl-C and SIGTERM for the block (e.g. while an output file is being opened, so an interrupt cannot
    land between creating the file and the code that finishes it on interrupt); the caller raises ``pending.exc``
    where it can handle it. Outside the main thread the block runs undeferred."""
    pending = Pending()
    if threading.current_thread() is not threading.main_thread():
        yield pending
        return

    def hold(signum: int, _frame: object) -> None:
        if pending.exc is None:
            pending.exc = Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()

    previous = {sig: signal.signal(sig, hold) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield pending
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def was_interrupted(reason: str) -> bool:
    """True for the ``metrics.reason`` of a run stopped by Ctrl-C or SIGTERM (in its loop or during setup)."""
    return reason.startswith("run did not complete: " + INTERRUPTED)
