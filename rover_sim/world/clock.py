"""The mission clock: local solar time over a drive, with the time flight software spent by activity.

Physics time is only the driving. On Mars a drive also spent time imaging and computing on a 20 MHz RAD6000:
about 160 s per visual-odometry step (seed 000, "2-3 min per step"), 24-30 s per stereo pair (seed 001) and
about 70 s per GESTALT autonav cycle including its stereo (seed 001). A drive of tens of metres therefore took
hours, during which the sun moved and the sol's time budget ran down.

:class:`MissionClock` accounts for it: the pipeline ``charge``s each activity as it happens (driving with the
physics time it took) and anything that depends on the time of day (the sun's direction, the drive budget) reads
``local_solar_time_h`` or ``drive_s``. No randomness; the same run gives the same clock.

A drive of several sols sleeps overnight: :meth:`MissionClock.sleep_until` charges the night as
``sleeping`` up to the next sol's wake-up time. Sleeping moves the time of day (and so the sun) but is not drive
time: ``drive_s`` (what a sol's drive-time budget counts) sums driving, imaging and computing only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

Activity = Literal["driving", "imaging", "computing", "sleeping"]
DRIVE_ACTIVITIES: tuple[Activity, ...] = ("driving", "imaging", "computing")  # the drive-time budget's
ACTIVITIES: tuple[Activity, ...] = (*DRIVE_ACTIVITIES, "sleeping")

SECONDS_PER_SOL = 88775.244  # one Mars solar day
VO_STEP_COMPUTE_S = 160.0  # seed 000: 2-3 min per VO update on the MER flight computer
STEREO_PAIR_COMPUTE_S = 27.0  # seed 001: 24-30 s per 256x256 stereo pair
AUTONAV_CYCLE_S = 70.0  # seed 001: GESTALT cycle (imaging + stereo + goodness + arc voting), about 70 s
IMAGE_PAIR_ACQUIRE_S = 10.0  # exposure, readout and binning of one pair (order of magnitude; not published)


@dataclass
class MissionClock:
    """Elapsed mission time since the drive started, split by activity; local solar time of day from it."""

    start_local_solar_time_h: float = 12.0
    by_activity_s: dict[str, float] = field(default_factory=lambda: {a: 0.0 for a in ACTIVITIES})

    def __post_init__(self) -> None:
        if not 0.0 <= self.start_local_solar_time_h < 24.0:
            raise ValueError(f"start_local_solar_time_h must be in [0, 24), got {self.start_local_solar_time_h}")

    def charge(self, activity: Activity, seconds: float) -> None:
        """Add ``seconds`` (>= 0) of ``activity`` to the clock."""
        if activity not in ACTIVITIES:
            raise ValueError(f"activity must be one of {ACTIVITIES}, got {activity!r}")
        if not seconds >= 0.0:
            raise ValueError(f"seconds must be >= 0, got {seconds}")
        self.by_activity_s[activity] += float(seconds)

    @property
    def elapsed_s(self) -> float:
        """Mission time since the start, sleeping included (what the time of day follows)."""
        return float(sum(self.by_activity_s.values()))

    @property
    def drive_s(self) -> float:
        """Drive time since the start: driving + imaging + computing (sleeping excluded)."""
        return float(sum(self.by_activity_s[a] for a in DRIVE_ACTIVITIES))

    @property
    def _hours_since_start_day_h(self) -> float:
        """Mars hours since the local midnight before the start."""
        return self.start_local_solar_time_h + 24.0 * self.elapsed_s / SECONDS_PER_SOL

    @property
    def local_solar_time_h(self) -> float:
        """Local (true) solar time in Mars hours (1/24 sol), wrapping at 24."""
        return self._hours_since_start_day_h % 24.0

    @property
    def sol_index(self) -> int:
        """Local midnights passed since the start (0 on the first day)."""
        return int((self._hours_since_start_day_h + 1e-9) // 24.0)  # a wake at 0 h is on the new sol

    def sleep_until(self, wake_local_solar_time_h: float) -> float:
        """Sleep to ``wake_local_solar_time_h`` of the next sol (after the next local midnight): charge the night
        as ``sleeping`` and return its length, s."""
        if not 0.0 <= wake_local_solar_time_h < 24.0:
            raise ValueError(f"wake_local_solar_time_h must be in [0, 24), got {wake_local_solar_time_h}")
        wake_h = 24.0 * (self.sol_index + 1) + wake_local_solar_time_h
        seconds = (wake_h - self._hours_since_start_day_h) * SECONDS_PER_SOL / 24.0
        self.charge("sleeping", seconds)
        return seconds

    def summary(self) -> dict[str, float]:
        """Seconds by activity, the drive-time total (``total_s``, sleeping excluded) and the local solar time at
        the end (for ``metrics.json``)."""
        out = {f"{a}_s": round(self.by_activity_s[a], 3) for a in DRIVE_ACTIVITIES}
        out["total_s"] = round(self.drive_s, 3)
        out["sleeping_s"] = round(self.by_activity_s["sleeping"], 3)
        out["local_solar_time_h"] = round(self.local_solar_time_h, 4)
        return out
