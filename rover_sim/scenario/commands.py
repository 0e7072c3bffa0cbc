"""The command sequence as MER was commanded (blind drives, arcs, turns, VO-corrected goto, autonav to a waypoint,
mast pointing, sleep to the next sol), keep-out zones, and the budgets of a sol's drive (``[sol]``)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from rover_sim.scenario.base import Spec


class DriveCmd(Spec):
    """Blind straight drive: ends when the wheels have turned ``distance_m``."""

    type: Literal["drive"]
    distance_m: float = Field(ge=-50.0, le=50.0)


class ArcCmd(Spec):
    type: Literal["arc"]
    radius_m: float = Field(ge=-1000.0, le=1000.0, description="> 0 turns left; |radius| >= 0.3 m.")
    distance_m: float = Field(ge=-50.0, le=50.0)

    @model_validator(mode="after")
    def _radius(self) -> ArcCmd:
        if abs(self.radius_m) < 0.3:
            raise ValueError("|radius_m| must be >= 0.3 m (use a turn command for a point turn)")
        return self


class TurnCmd(Spec):
    type: Literal["turn"]
    angle_deg: float = Field(ge=-360.0, le=360.0)


class GotoCmd(Spec):
    """Drive to a point using the onboard (VO-corrected if VO is on) pose, in steps of ``nav.vo_step_m``."""

    type: Literal["goto"]
    x_m: float = Field(ge=-1.0e4, le=1.0e4)
    y_m: float = Field(ge=-1.0e4, le=1.0e4)
    tolerance_m: float = Field(0.2, gt=0.0, le=10.0)
    max_distance_m: float = Field(60.0, gt=0.0, le=500.0, description="Commanded-travel budget before giving up.")


class AutonavCmd(Spec):
    """GESTALT autonomous navigation to a waypoint."""

    type: Literal["autonav"]
    x_m: float = Field(ge=-1.0e4, le=1.0e4)
    y_m: float = Field(ge=-1.0e4, le=1.0e4)
    tolerance_m: float = Field(1.0, gt=0.0, le=10.0)
    step_m: float = Field(0.5, ge=0.35, le=1.0, description="Drive per GESTALT cycle (MER: 35 cm to 1 m).")
    max_cycles: int = Field(120, ge=1, le=2000)


class MastCmd(Spec):
    type: Literal["mast"]
    pan_deg: float = Field(ge=-180.0, le=180.0)
    tilt_deg: float = Field(ge=-70.0, le=85.0, description="Elevation: negative looks down.")


class SleepCmd(Spec):
    """End of sol: the rover parks, wheels held, and sleeps until the next sol's wake-up time on the
    mission clock; the next sol's budgets start then. Needs a ``[sol]`` table."""

    type: Literal["sleep"]
    wake_local_solar_time_h: float | None = Field(
        None, ge=0.0, lt=24.0,
        description="Local solar time the rover wakes at, next sol (default: the time of day the drive started).",
    )  # fmt: skip


Command = Annotated[
    DriveCmd | ArcCmd | TurnCmd | GotoCmd | AutonavCmd | MastCmd | SleepCmd, Field(discriminator="type")
]


class KeepOut(Spec):
    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$")
    x_m: float = Field(ge=-1.0e4, le=1.0e4)
    y_m: float = Field(ge=-1.0e4, le=1.0e4)
    radius_m: float = Field(gt=0.0, le=100.0, description="Halt when the onboard pose comes this close.")


class SolSpec(Spec):
    """``[sol]``: the day's drive as MER flew it: the commands run until the drive-time budget (mission
    clock: driving + imaging + computing, ``rover_sim/world/clock.py``) or the odometry distance budget is spent.
    A drive of several sols separates them with ``sleep`` commands: the budgets apply to each sol, and a sol whose
    budget is spent skips the rest of its commands up to the next ``sleep``. Long drives keep fewer poses
    (``pose_stride``) so memory and the recording grow slowly with distance."""

    max_time_s: float = Field(gt=0.0, le=86400.0, description="Drive-time budget of each sol on the mission clock, s.")
    max_distance_m: float | None = Field(None, gt=0.0, le=5000.0, description="Odometry budget of each sol, m.")
    start_local_solar_time_h: float = Field(11.0, ge=0.0, lt=24.0, description="Local solar time at the start.")
    pose_stride: int = Field(1, ge=1, le=64, description="Ticks (8 Hz) between kept poses and logged poses.")
    vo_min_slope_deg: float | None = Field(
        None, ge=0.0, le=45.0, description="Blind drives image VO only where the onboard tilt exceeds this (MER)."
    )
    benchmark_only: bool = Field(False, description="A bench traverse case, not part of the scenario catalogue.")
