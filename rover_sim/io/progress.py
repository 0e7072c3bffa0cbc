"""Progress of a run in simulated seconds: a live tqdm bar on a terminal, plain lines in a log.

A tqdm bar redraws itself with carriage returns; written to a file or a pipe (a CI log, ``2> run.log``) every redraw
becomes part of the log. So on a terminal :class:`SimProgress` shows the bar, and otherwise writes one ordinary line
(``name: 42 sim-s, 61 s``) at most every :data:`LOG_INTERVAL_S` seconds of wall time, and a last one when closed.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

LOG_INTERVAL_S = 10.0  # wall seconds between progress lines when stderr is not a terminal
BAR_FORMAT = "{desc}: {n:.0f} sim-s [{elapsed}, {rate_fmt}]"


def is_terminal(stream: TextIO | None) -> bool:
    """Whether ``stream`` is an interactive terminal (False for files, pipes and closed or missing streams)."""
    try:
        return stream is not None and bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty(), or a closed file
        return False


class SimProgress:
    """Simulated time reached, shown every simulated second at most (a bar) or every ``LOG_INTERVAL_S`` (lines)."""

    def __init__(self, desc: str, stream: TextIO | None = None) -> None:
        self.desc = desc
        self.stream = stream if stream is not None else sys.stderr
        self.t_s = 0.0
        self.t0 = time.monotonic()
        self.last_line = self.t0
        self.bar = None
        if is_terminal(self.stream):
            from tqdm import tqdm

            self.bar = tqdm(desc=desc, unit="sim-s", mininterval=1.0, bar_format=BAR_FORMAT, file=self.stream)

    def update(self, t_s: float) -> None:
        """The run reached ``t_s`` simulated seconds."""
        if self.bar is not None:
            if t_s - self.bar.n >= 1.0:
                self.bar.update(t_s - self.bar.n)
            return
        self.t_s = t_s
        now = time.monotonic()
        if now - self.last_line >= LOG_INTERVAL_S:
            self.last_line = now
            self.line(now)

    def line(self, now: float) -> None:
        self.stream.write(f"{self.desc}: {self.t_s:.0f} sim-s, {now - self.t0:.0f} s\n")
        self.stream.flush()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        elif self.t_s > 0.0:
            self.line(time.monotonic())
