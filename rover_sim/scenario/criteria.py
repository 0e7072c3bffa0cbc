"""``[pass]``: the scenario's pass criterion (every set bound must hold; :mod:`rover_sim.runtime.acceptance` judges)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from rover_sim.scenario.base import Spec


class PassSpec(Spec):
    """The scenario's pass criterion; every set bound must hold."""

    max_vo_error_pct: float | None = Field(None, gt=0.0, le=100.0)
    min_dr_error_pct: float | None = Field(None, ge=0.0, le=1000.0)
    max_dr_error_pct: float | None = Field(None, gt=0.0, le=1000.0)
    min_vo_convergence_pct: float | None = Field(None, ge=0.0, le=100.0)
    justified_refusals: bool = Field(
        False,
        description="min_vo_convergence_pct counts only steps where some pointing had texture: a refusal logged as "
        "'no pointing had texture' is justified (featureless ground, issue #17).",
    )
    min_max_slip_pct: float | None = Field(None, ge=0.0, le=500.0)
    max_max_slip_pct: float | None = Field(None, ge=0.0, le=500.0)
    max_false_positives: int | None = Field(None, ge=0, le=1000)
    expect_halt: Literal["keep_out", "slip_limit", "vo_failures"] | None = None
    expect_dead_reckoning_clear: bool = Field(
        False, description="At a keep-out halt, dead reckoning alone still believes the rover outside the zone."
    )
    goal_within_m: float | None = Field(None, gt=0.0, le=100.0, description="Truth within this of the last goal.")
    max_body_collisions: int | None = Field(
        None, ge=0, le=1000, description="Ticks with the body touching anything, or any part touching a rock >= 25 cm."
    )
    # embedding (issue #13, purgatory_ripple): the wheels' state at the end of the run, from truth
    min_final_sinkage_m: float | None = Field(
        None, ge=0.0, le=0.5,
        description="Mean depth of the six wheels' bottoms below the undisturbed ground at the end (deformable).",
    )  # fmt: skip
    max_final_sinkage_m: float | None = Field(None, ge=0.0, le=0.5, description="Upper bound of the same.")
    min_final_slip_pct: float | None = Field(
        None, ge=0.0, le=500.0, description="Slip over the last metre of commanded wheel travel (truth)."
    )

    def judges_wheels(self) -> bool:
        """True when a criterion needs the end-of-run wheel metrics (``metrics.extra["wheels"]``)."""
        bounds = (self.min_final_sinkage_m, self.max_final_sinkage_m, self.min_final_slip_pct)
        return any(b is not None for b in bounds)
