"""The sol's drive budget: the mission clock charged by activity, distance by drive mode, and the stop.

MER drove a sol as a command sequence: blind segments the operators planned, then autonav for the rest of the
day's time, visual odometry only where slopes called for it (Biesiadecki & Maimone 2006; Maimone et al. 2007).
The day's drive ended when the drive-time budget or the distance budget ran out. :class:`SolBudget` reads the
world's :class:`~rover_sim.world.clock.MissionClock` (the one clock of the run, also moving the sun: the world
charges driving with physics time and imaging per stereo pair; the pipeline charges computing per VO step and
GESTALT cycle with the flight computer's published costs) and raises :class:`BudgetSpent` from the 8 Hz tick when
either budget is spent. Distances are split by the mode the rover drove in.

Long traverses were flown as one drive a sol, each day's traverse planned anew, the rover operating "about four
hours a day" and asleep overnight (Maimone et al. 2007, seed 001). A ``sleep`` command ends a sol
(:meth:`SolBudget.sleep`): the night is charged as ``sleeping`` up to the next sol's wake-up time, and the budgets
start again, so ``max_time_s`` and ``max_distance_m`` apply to each sol (from the start or from the last sleep).
The ``sol`` block of metrics.json keeps its totals over the run and lists each sol in ``sols``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rover_sim.scenario.commands import SolSpec
from rover_sim.world.clock import DRIVE_ACTIVITIES, MissionClock

MODES = ("blind", "blind_vo", "autonav")


class BudgetSpent(Exception):
    """The sol's drive-time or distance budget is spent: the drive ends (an outcome, not a fault)."""


@dataclass
class SolRecord:
    """One sol of the drive: where its budgets start, and how it ended."""

    number: int  # 1 for the first sol of the drive
    start_local_solar_time_h: float
    start_by_activity_s: dict[str, float]
    start_distance_by_mode_m: dict[str, float]
    start_odometry_m: float
    summary: dict | None = None  # set when the sol is closed by a sleep


@dataclass
class SolBudget:
    """Budgets of a drive of one or more sols, the mission clock and the distance driven in each mode."""

    spec: SolSpec
    clock: MissionClock  # the world's clock (charged by the world and the pipeline)
    mode: str = "blind"
    distance_by_mode_m: dict[str, float] = field(default_factory=lambda: dict.fromkeys(MODES, 0.0))
    stopped_by: str | None = None  # what ended the current sol's drive early (a budget), None so far
    sols: list[SolRecord] = field(default_factory=list)
    _autonav: dict[int, dict] = field(default_factory=dict)  # sol number -> cycles, backtracks, last outcome
    _odometry_m: float = 0.0
    _last_t_s: float | None = None
    _last_xy: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.sols.append(self._open(1, 0.0))

    @property
    def current(self) -> SolRecord:
        return self.sols[-1]

    def _open(self, number: int, odometry_m: float) -> SolRecord:
        return SolRecord(number, self.clock.local_solar_time_h, dict(self.clock.by_activity_s),
                         dict(self.distance_by_mode_m), odometry_m)  # fmt: skip

    def on_tick(self, t_s: float, position_m: np.ndarray, odometry_m: float) -> None:
        """Distance since the last tick by mode (truth distance, for the summary); then the budgets (the clock,
        driving charged up to ``t_s`` by the caller, and odometry, as flight software knew it). Raises
        :class:`BudgetSpent`."""
        if self._last_t_s is not None:
            self.distance_by_mode_m[self.mode] += float(np.linalg.norm(position_m[:2] - self._last_xy))
        self._last_t_s, self._last_xy = t_s, np.asarray(position_m[:2], dtype=float).copy()
        self._odometry_m = float(odometry_m)
        self.check(odometry_m)

    def check(self, odometry_m: float) -> None:
        """Raise :class:`BudgetSpent` if this sol's drive time (sleeping excluded) or odometry is spent."""
        sol = self.current
        drive_s = self.clock.drive_s - sum(sol.start_by_activity_s[a] for a in DRIVE_ACTIVITIES)
        if drive_s >= self.spec.max_time_s:
            self.stopped_by = "time"
            raise BudgetSpent(f"drive-time budget spent ({drive_s:.0f} s of {self.spec.max_time_s:.0f})")
        driven_m = odometry_m - sol.start_odometry_m
        if self.spec.max_distance_m is not None and driven_m >= self.spec.max_distance_m:
            self.stopped_by = "distance"
            raise BudgetSpent(f"distance budget spent ({driven_m:.1f} m of {self.spec.max_distance_m:.1f})")

    def note_autonav(self, cycles: int, backtracks: int, outcome: str) -> None:
        """An autonav command of this sol ended (or was cut by a budget: empty ``outcome``)."""
        a = self._autonav.setdefault(self.current.number, {"cycles": 0, "backtracks": 0, "outcome": ""})
        a["cycles"] += cycles
        a["backtracks"] += backtracks
        a["outcome"] = outcome or "sol budget spent"

    def sleep(self, wake_local_solar_time_h: float) -> float:
        """End this sol: close its summary, sleep the night on the clock (charged as ``sleeping``) to
        ``wake_local_solar_time_h`` of the next sol, and start the next sol's budgets. Returns the night, s."""
        closed = self.current
        closed.summary = self._sol_summary(closed, self.stopped_by or "sleep")
        slept_s = self.clock.sleep_until(wake_local_solar_time_h)
        closed.summary["time_by_activity_s"]["sleeping_s"] = round(slept_s, 3)
        self.stopped_by = None
        self.sols.append(self._open(closed.number + 1, self._odometry_m))
        return slept_s

    def _sol_summary(self, sol: SolRecord, stopped_by: str) -> dict:
        by = self.clock.by_activity_s
        time_s = {f"{a}_s": round(by[a] - sol.start_by_activity_s[a], 3) for a in DRIVE_ACTIVITIES}
        time_s["total_s"] = round(sum(by[a] - sol.start_by_activity_s[a] for a in DRIVE_ACTIVITIES), 3)
        time_s["sleeping_s"] = 0.0
        out = {
            "sol": sol.number,
            "time_by_activity_s": time_s,
            "distance_by_mode_m": {
                k: round(v - sol.start_distance_by_mode_m[k], 3) for k, v in self.distance_by_mode_m.items()
            },
            "odometry_m": round(self._odometry_m - sol.start_odometry_m, 3),
            "stopped_by": stopped_by,
            "start_local_solar_time_h": round(sol.start_local_solar_time_h, 4),
            "local_solar_time_h": round(self.clock.local_solar_time_h, 4),
        }
        if sol.number in self._autonav:
            out["autonav"] = dict(self._autonav[sol.number])
        return out

    def summary(self) -> dict:
        """The ``sol`` block of metrics.json: totals over the run (time by activity, distance by mode, what ended
        the drive) and ``sols``, one summary per sol (the last one as it is now)."""
        stopped = self.stopped_by or "commands done"
        sols = [s.summary for s in self.sols[:-1]] + [self._sol_summary(self.current, stopped)]
        return {
            "time_by_activity_s": self.clock.summary(),
            "distance_by_mode_m": {k: round(v, 3) for k, v in self.distance_by_mode_m.items()},
            "stopped_by": stopped,
            "max_time_s": self.spec.max_time_s,
            "max_distance_m": self.spec.max_distance_m,
            "sols": sols,
        }
