"""``[pass]``: the scenario's pass criterion (every set bound must hold; :mod:`rover_sim.runtime.acceptance` judges)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from rover_sim.scenario.base import Spec

# metrics a distribution criterion may bound (read from metrics.json: rover_sim.bench.seeded.METRICS)
DISTRIBUTION_METRICS = ("vo_error_pct", "dr_error_pct", "vo_convergence_pct", "max_slip_pct", "goal_distance_m",
                        "false_positives", "distance_m")  # fmt: skip


class DistributionSpec(Spec):
    """``[pass.distribution]``: criteria over seeds (``bench suite --seeds``): at least ``min_pass_rate`` of the
    seeds meet the per-run criteria (default: ``acceptance.DEFAULT_MIN_PASS_RATE``) and every bound holds."""

    min_pass_rate: float | None = Field(None, ge=0.0, le=1.0, description="Fraction of seeds that must pass.")
    max_median: dict[str, float] = Field(default_factory=dict, description="metric -> upper bound of its median")
    min_median: dict[str, float] = Field(default_factory=dict, description="metric -> lower bound of its median")
    max_p90: dict[str, float] = Field(default_factory=dict, description="metric -> upper bound of its 90th pct")

    @model_validator(mode="after")
    def _known_metrics(self) -> DistributionSpec:
        for table in ("max_median", "min_median", "max_p90"):
            for key in getattr(self, table):
                if key not in DISTRIBUTION_METRICS:
                    raise ValueError(f"{table}: unknown metric {key!r} (allowed: {', '.join(DISTRIBUTION_METRICS)})")
        return self


class PassSpec(Spec):
    """The scenario's pass criterion; every set bound must hold."""

    max_vo_error_pct: float | None = Field(None, gt=0.0, le=100.0)
    min_dr_error_pct: float | None = Field(None, ge=0.0, le=1000.0)
    max_dr_error_pct: float | None = Field(None, gt=0.0, le=1000.0)
    min_vo_convergence_pct: float | None = Field(None, ge=0.0, le=100.0)
    min_vo_textured_convergence_pct: float | None = Field(
        None, ge=0.0, le=100.0,
        description="VO convergence over the textured steps: both pairs of the step see >= 50 % textured ground "
        "(judged from truth by the evaluator; a refusal is never convergence).",
    )  # fmt: skip
    min_max_slip_pct: float | None = Field(None, ge=0.0, le=500.0)
    max_max_slip_pct: float | None = Field(None, ge=0.0, le=500.0)
    max_false_positives: int | None = Field(None, ge=0, le=1000)
    expect_halt: Literal["keep_out", "slip_limit", "vo_failures"] | None = None
    expect_dead_reckoning_clear: bool = Field(
        False, description="At a keep-out halt, dead reckoning alone still believes the rover outside the zone."
    )
    goal_within_m: float | None = Field(None, gt=0.0, le=100.0, description="Truth within this of the last goal.")
    max_site_error_vs_dr: float | None = Field(
        None, gt=0.0, le=1.0,
        description="The onboard pose's mean horizontal error at the sites (the end of every goto) is at most this "
        "fraction of dead reckoning's (dead reckoning alone scores 1).",
    )  # fmt: skip
    max_body_collisions: int | None = Field(
        None, ge=0, le=1000, description="Ticks with the body touching anything, or any part touching a rock >= 25 cm."
    )
    # embedding (purgatory_ripple): the wheels' state at the end of the run, from truth
    min_final_sinkage_m: float | None = Field(
        None, ge=0.0, le=0.5,
        description="Mean depth of the six wheels' bottoms below the undisturbed ground at the end (deformable).",
    )  # fmt: skip
    max_final_sinkage_m: float | None = Field(None, ge=0.0, le=0.5, description="Upper bound of the same.")
    min_final_slip_pct: float | None = Field(
        None, ge=0.0, le=500.0, description="Slip over the last metre of commanded wheel travel (truth)."
    )

    distribution: DistributionSpec = Field(default_factory=DistributionSpec)

    def judges_wheels(self) -> bool:
        """True when a criterion needs the end-of-run wheel metrics (``metrics.extra["wheels"]``)."""
        bounds = (self.min_final_sinkage_m, self.max_final_sinkage_m, self.min_final_slip_pct)
        return any(b is not None for b in bounds)
