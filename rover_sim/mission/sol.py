"""The sol's drive budget (issue #18): the mission clock charged by activity, distance by drive mode, and the stop.

MER drove a sol as a command sequence: blind segments the operators planned, then autonav for the rest of the
day's time, visual odometry only where slopes called for it (Biesiadecki & Maimone 2006; Maimone et al. 2007).
The day's drive ended when the drive-time budget or the distance budget ran out. :class:`SolBudget` reads the
world's :class:`~rover_sim.mission.clock.MissionClock` (the one clock of the run, also moving the sun: the world
charges driving with physics time and imaging per stereo pair; the pipeline charges computing per VO step and
GESTALT cycle with the flight computer's published costs) and raises :class:`BudgetSpent` from the 8 Hz tick when
either budget is spent. Distances are split by the mode the rover drove in.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rover_sim.mission.clock import MissionClock
from rover_sim.mission.scenario import SolSpec

MODES = ("blind", "blind_vo", "autonav")


class BudgetSpent(Exception):
    """The sol's drive-time or distance budget is spent: the drive ends (an outcome, not a fault)."""


@dataclass
class SolBudget:
    """Budgets of one sol's drive, the mission clock and the distance driven in each mode."""

    spec: SolSpec
    clock: MissionClock  # the world's clock (charged by the world and the pipeline)
    mode: str = "blind"
    distance_by_mode_m: dict[str, float] = field(default_factory=lambda: dict.fromkeys(MODES, 0.0))
    stopped_by: str | None = None
    _last_t_s: float | None = None
    _last_xy: np.ndarray | None = None

    def on_tick(self, t_s: float, position_m: np.ndarray, odometry_m: float) -> None:
        """Distance since the last tick by mode (truth distance, for the summary); then the budgets (the clock,
        driving charged up to ``t_s`` by the caller, and odometry, as flight software knew it). Raises
        :class:`BudgetSpent`."""
        if self._last_t_s is not None:
            self.distance_by_mode_m[self.mode] += float(np.linalg.norm(position_m[:2] - self._last_xy))
        self._last_t_s, self._last_xy = t_s, np.asarray(position_m[:2], dtype=float).copy()
        self.check(odometry_m)

    def check(self, odometry_m: float) -> None:
        if self.clock.elapsed_s >= self.spec.max_time_s:
            self.stopped_by = "time"
            raise BudgetSpent(f"drive-time budget spent ({self.clock.elapsed_s:.0f} s of {self.spec.max_time_s:.0f})")
        if self.spec.max_distance_m is not None and odometry_m >= self.spec.max_distance_m:
            self.stopped_by = "distance"
            raise BudgetSpent(f"distance budget spent ({odometry_m:.1f} m of {self.spec.max_distance_m:.1f})")

    def summary(self) -> dict:
        """The ``sol`` block of metrics.json: time by activity, distance by mode, what ended the drive."""
        return {
            "time_by_activity_s": self.clock.summary(),
            "distance_by_mode_m": {k: round(v, 3) for k, v in self.distance_by_mode_m.items()},
            "stopped_by": self.stopped_by or "commands done",
            "max_time_s": self.spec.max_time_s,
            "max_distance_m": self.spec.max_distance_m,
        }
