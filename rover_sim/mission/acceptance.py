"""Every pass criterion in one place: the scenario judge and the benchmarks' acceptance bars.

A scenario's own criteria live in its ``[pass]`` table (:class:`rover_sim.mission.scenario.PassSpec`) and are
judged by :func:`judge`; the benchmarks' bars are the constants below (each with the issue or paper it comes from).
The CLI and the benchmark modules read them from here and nowhere else.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from rover_sim.mission.evaluator import FALSE_POSITIVE_FRACTION as EVAL_FALSE_POSITIVE_FRACTION
from rover_sim.mission.evaluator import FALSE_POSITIVE_M as EVAL_FALSE_POSITIVE_M
from rover_sim.mission.evaluator import MIN_DISTANCE_FOR_PCT_M, Metrics
from rover_sim.mission.scenario import KeepOut, PassSpec

TALL_ROCK_M = 0.25  # GESTALT must avoid touching rocks at least this tall (wheel or body)
FALSE_POSITIVE_M = EVAL_FALSE_POSITIVE_M  # false positive: error > max(this, FALSE_POSITIVE_FRACTION x step)
FALSE_POSITIVE_FRACTION = EVAL_FALSE_POSITIVE_FRACTION


@dataclass(frozen=True)
class AutonavBar:
    """``bench autonav``: reach the goal on >= 95 % of fields, never touch a tall rock, plan within 50 ms."""

    min_reached_frac: float = 0.95
    max_collisions: int = 0
    max_cycle_ms: float = 50.0


@dataclass(frozen=True)
class StereoBar:
    """``bench stereo``: at most 1.5x StereoBM's time, fewer bad-1px pixels than StereoBM."""

    max_time_ratio: float = 1.5


@dataclass(frozen=True)
class RenderBar:
    """``bench render``: a 256x256 navcam pair with shadows within 40 ms."""

    max_pair_256_shadows_ms: float = 40.0


@dataclass(frozen=True)
class DimesBar:
    """``bench dimes``: 1-sigma horizontal velocity error <= 1.5 m/s (MER DIMES requirement), >= 50 descents, of
    which >= 90 % give an accepted estimate (issue #17: one accepted descent of 50 must not pass)."""

    max_velocity_error_1sigma_m_s: float = 1.5
    min_runs: int = 50
    min_accepted_frac: float = 0.90


@dataclass(frozen=True)
class RocksBar:
    """``bench rocks`` (seed 004): extraction, modelling, matching and site-to-site error."""

    recall: float = 0.90
    precision: float = 0.90
    median_rms_m: float = 0.04
    match_correct_frac: float = 0.90
    site_error_pct: float = 2.0
    model_type_match_frac_well_observed: float = 0.80


@dataclass(frozen=True)
class SweepBar:
    """``bench sweep``: two workers take at most 0.65 of the serial wall time."""

    max_parallel_ratio: float = 0.65


@dataclass(frozen=True)
class WheelBand:
    """One cumulative slip-angle band of ``bench wheel``: the largest RMSE allowed over all rows of one wheel whose
    slip angle is at most ``max_slip_angle_deg`` (every slip from -1 to 0.9)."""

    max_slip_angle_deg: float
    drawbar_over_load: float
    lateral_over_load: float
    sinkage_mm: float

    @property
    def key(self) -> str:
        return f"0-{self.max_slip_angle_deg:g}"


@dataclass(frozen=True)
class WheelBar:
    """``bench wheel``: the wheel-soil law on the single-wheel rig against measured single-wheel tests, per wheel.

    RMSE of drawbar pull / load, lateral force / load and sinkage over the rows of each cumulative slip-angle band
    (issue: soil validated against measured wheel tests); and at 0 deg the predicted drawbar pull non-decreasing
    in slip from -1 to 0.9 (a sweep of the rig at the wheel's mean 0 deg load; a step may fall by at most
    ``monotone_tolerance`` of the load, the rig's averaging noise: a tenth of the 0.02 trial-to-trial spread)."""

    bands: tuple[WheelBand, ...] = (
        WheelBand(30.0, 0.10, 0.20, 8.0),
        WheelBand(60.0, 0.15, 0.25, 8.0),
        WheelBand(90.0, 0.25, 0.50, 12.0),
    )
    monotone_slips: tuple[float, float] = (-1.0, 0.9)
    monotone_tolerance: float = 0.002


WHEEL_QUANTITIES = ("drawbar_over_load", "lateral_over_load", "sinkage_mm")


def judge_wheel(rmse_by_band: dict[str, dict[str, dict[str, float | None]]],
                monotone_drops: dict[str, float]) -> tuple[bool, list[str]]:  # fmt: skip
    """``bench wheel``'s verdict: ``rmse_by_band[wheel][band key][quantity]`` (None: not measured, not judged) and
    ``monotone_drops[wheel]`` (the largest fall of DP/load between successive slips of the 0 deg sweep, 0 if it never
    falls). Returns (passed, the reasons it failed); nothing measured at all is a failure."""
    bar, reasons, judged = WHEEL, [], 0
    for wheel, bands in rmse_by_band.items():
        for band in bar.bands:
            got = bands.get(band.key, {})
            for q in WHEEL_QUANTITIES:
                v, limit = got.get(q), getattr(band, q)
                if v is None:
                    continue
                judged += 1
                if v > limit:
                    reasons.append(f"{wheel} {band.key} deg: {q} RMSE {v:.3g} > {limit:g}")
    for wheel, drop in monotone_drops.items():
        judged += 1
        if drop > bar.monotone_tolerance:
            reasons.append(f"{wheel} 0 deg: drawbar pull / load falls by {drop:.3f} (> {bar.monotone_tolerance:g}) "
                           f"between successive slips")  # fmt: skip
    if not judged:
        reasons.append("nothing to judge: no measured rows and no 0 deg rows")
    return not reasons, reasons


AUTONAV = AutonavBar()
STEREO = StereoBar()
RENDER = RenderBar()
DIMES = DimesBar()
ROCKS = RocksBar()
SWEEP = SweepBar()
WHEEL = WheelBar()


def describe(p: PassSpec) -> str:
    """The scenario's criteria as one line (for benchmark tables)."""
    parts = []
    if p.max_vo_error_pct is not None:
        parts.append(f"VO <= {p.max_vo_error_pct:g} %")
    if p.min_dr_error_pct is not None:
        parts.append(f"DR >= {p.min_dr_error_pct:g} %")
    if p.max_dr_error_pct is not None:
        parts.append(f"DR <= {p.max_dr_error_pct:g} %")
    if p.min_vo_convergence_pct is not None:
        alt = " or justified refusal" if p.justified_refusals else ""
        parts.append(f"convergence >= {p.min_vo_convergence_pct:g} %{alt}")
    if p.min_max_slip_pct is not None:
        parts.append(f"slip >= {p.min_max_slip_pct:g} %")
    if p.max_max_slip_pct is not None:
        parts.append(f"slip <= {p.max_max_slip_pct:g} %")
    if p.max_false_positives is not None:
        parts.append(f"{p.max_false_positives} false positives")
    if p.expect_halt is not None:
        parts.append(f"{p.expect_halt} halt")
    if p.goal_within_m is not None:
        parts.append(f"goal within {p.goal_within_m:g} m")
    if p.max_body_collisions is not None:
        parts.append(f"<= {p.max_body_collisions} collisions")
    if p.min_final_sinkage_m is not None:
        parts.append(f"final sinkage >= {p.min_final_sinkage_m:g} m")
    if p.max_final_sinkage_m is not None:
        parts.append(f"final sinkage <= {p.max_final_sinkage_m:g} m")
    if p.min_final_slip_pct is not None:
        parts.append(f"final slip >= {p.min_final_slip_pct:g} %")
    return ", ".join(parts) or "runs to completion"


def judge(
    m: Metrics, p: PassSpec, *, error: str | None, keep_out_info: dict | None, keep_out: list[KeepOut]
) -> tuple[bool, str]:
    """Pass/fail of one run against its scenario's ``[pass]`` criteria; the reason names every unmet bound."""
    if error:
        return False, f"run did not complete: {error}"
    fails: list[str] = []

    def need(ok: bool, text: str) -> None:
        if not ok:
            fails.append(text)

    short = f"not measured: {m.distance_m} m travelled (< {MIN_DISTANCE_FOR_PCT_M} m)"
    if p.max_vo_error_pct is not None:
        if m.vo_error_pct is None:
            fails.append(f"VO error {short}" if m.vo_error_m is not None else "VO error not measured: VO off")
        else:
            need(m.vo_error_pct <= p.max_vo_error_pct, f"VO error {m.vo_error_pct} % > {p.max_vo_error_pct} %")
    if (p.min_dr_error_pct is not None or p.max_dr_error_pct is not None) and m.dr_error_pct is None:
        fails.append(f"DR error {short}")
    elif p.min_dr_error_pct is not None:
        need(m.dr_error_pct >= p.min_dr_error_pct, f"DR error {m.dr_error_pct} % < {p.min_dr_error_pct} %")
    if p.max_dr_error_pct is not None and m.dr_error_pct is not None:
        need(m.dr_error_pct <= p.max_dr_error_pct, f"DR error {m.dr_error_pct} % > {p.max_dr_error_pct} %")
    if p.min_vo_convergence_pct is not None:
        conv, what = m.vo_convergence_pct, "VO convergence"
        if p.justified_refusals and m.vo_refusals_justified:
            textured = m.vo_steps - m.vo_refusals_justified  # steps where some pointing had texture
            conv = round(100.0 * m.vo_accepted / textured, 2) if textured else 100.0
            what = f"VO convergence on textured steps ({m.vo_refusals_justified} justified refusals)"
        need(conv is not None and conv >= p.min_vo_convergence_pct, f"{what} {conv} % < {p.min_vo_convergence_pct} %")
    if p.min_max_slip_pct is not None:
        need(m.max_slip_pct >= p.min_max_slip_pct, f"max slip {m.max_slip_pct} % < {p.min_max_slip_pct} %")
    if p.max_max_slip_pct is not None:
        need(m.max_slip_pct <= p.max_max_slip_pct, f"max slip {m.max_slip_pct} % > {p.max_max_slip_pct} %")
    if p.max_false_positives is not None:
        need(
            m.false_positives <= p.max_false_positives,
            f"{m.false_positives} VO false positives > {p.max_false_positives}",
        )
    if p.expect_halt is not None:
        need(m.halted == p.expect_halt, f"expected a {p.expect_halt} halt, got {m.halted}")
    elif m.halted is not None:
        fails.append(f"unexpected {m.halted} halt")
    if p.expect_dead_reckoning_clear:
        info = keep_out_info
        need(
            info is not None
            and info["dead_reckoning_distance_m"] > info["onboard_distance_m"] + 0.1
            and any(info["dead_reckoning_distance_m"] >= z.radius_m for z in keep_out),
            "dead reckoning did not believe the rover clear at the keep-out halt",
        )
    if p.goal_within_m is not None:
        need(
            m.goal_distance_m is not None and m.goal_distance_m <= p.goal_within_m,
            f"ended {m.goal_distance_m} m from the goal (> {p.goal_within_m} m)",
        )
    if p.max_body_collisions is not None:
        need(m.body_collisions <= p.max_body_collisions, f"{m.body_collisions} body-collision ticks")
        need(
            m.tall_rock_contacts <= p.max_body_collisions,
            f"{m.tall_rock_contacts} ticks touching rocks taller than {TALL_ROCK_M} m",
        )
    if p.judges_wheels():
        _judge_wheels(m.extra.get("wheels"), p, need)
    return (not fails, "; ".join(fails) if fails else "all criteria met")


def _judge_wheels(wheels: dict | None, p: PassSpec, need: Callable[[bool, str], None]) -> None:
    """The embedding criteria (purgatory_ripple): the wheels' sinkage and slip at the end of the run."""
    if wheels is None:
        need(False, "final wheel sinkage and slip not measured")
        return
    z, slip = wheels["final_sinkage_m"], wheels["final_slip_pct"]
    if p.min_final_sinkage_m is not None:
        need(z >= p.min_final_sinkage_m, f"final sinkage {z} m < {p.min_final_sinkage_m} m")
    if p.max_final_sinkage_m is not None:
        need(z <= p.max_final_sinkage_m, f"final sinkage {z} m > {p.max_final_sinkage_m} m")
    if p.min_final_slip_pct is not None:
        need(slip is not None and slip >= p.min_final_slip_pct, f"final slip {slip} % < {p.min_final_slip_pct} %")
