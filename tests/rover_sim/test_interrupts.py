"""rover_sim.interrupts: signals held while an output file is opened, then raised where they can be handled."""

from __future__ import annotations

import os
import signal

import pytest

from rover_sim import interrupts
from rover_sim.errors import Terminated


@pytest.mark.parametrize(("sig", "kind"), [(signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, Terminated)])
def test_deferred_holds_the_signal_and_hands_it_back(sig, kind):
    before = signal.getsignal(sig)
    reached_end = False
    with interrupts.deferred() as pending:
        os.kill(os.getpid(), sig)
        reached_end = True
    assert reached_end and type(pending.exc) is kind
    assert signal.getsignal(sig) is before  # the previous handler is back


def test_deferred_without_a_signal_has_nothing_pending():
    with interrupts.deferred() as pending:
        pass
    assert pending.exc is None
