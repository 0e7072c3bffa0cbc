"""Every pass criterion in one place: the scenario judge and the benchmarks' acceptance bars.

A scenario's own criteria live in its ``[pass]`` table (:class:`rover_sim.scenario.criteria.PassSpec`) and are
judged by :func:`judge`; the benchmarks' bars are the constants below (each with the issue or paper it comes from).
The CLI and the benchmark modules read them from here and nowhere else.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from rover_sim.runtime.evaluator import FALSE_POSITIVE_FRACTION as EVAL_FALSE_POSITIVE_FRACTION
from rover_sim.runtime.evaluator import FALSE_POSITIVE_M as EVAL_FALSE_POSITIVE_M
from rover_sim.runtime.evaluator import MIN_DISTANCE_FOR_PCT_M, Metrics
from rover_sim.scenario.commands import KeepOut
from rover_sim.scenario.criteria import DistributionSpec, PassSpec

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
class GlobalLocBar:
    """``bench globalloc``: on rocky plains and crater rims >= 95 % of stops fixed within ``false_fix_m``, median
    error <= 0.25 m, 90th percentile <= 0.5 m, <= 30 s of CPU per fix (Perseverance's Mars Global Localization:
    ~25 cm in ~2 min); on every terrain no false fix (accepted and more than 1 m off); >= 40 stops over >= 8 seeds
    per terrain."""

    fixed_terrains: tuple[str, ...] = ("rocky_plains", "crater_rim")
    min_fixed_frac: float = 0.95
    max_median_error_m: float = 0.25
    max_p90_error_m: float = 0.5
    max_false_fixes: int = 0
    false_fix_m: float = 1.0
    max_compute_s: float = 30.0
    min_stops: int = 40
    min_seeds: int = 8


AUTONAV = AutonavBar()
STEREO = StereoBar()
RENDER = RenderBar()
DIMES = DimesBar()
ROCKS = RocksBar()
SWEEP = SweepBar()
GLOBALLOC = GlobalLocBar()


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


# ================================================================================ figures over seeds
# A scenario's claim is a distribution over seeds (`bench suite --seeds`): its verdict and the regression gate's.

DEFAULT_MIN_PASS_RATE = 0.75  # without [pass.distribution] min_pass_rate: this fraction of seeds must pass


@dataclass(frozen=True)
class DistributionVerdict:
    """A scenario over seeds: the fraction of seeds meeting the per-run criteria, and the verdict with its reasons
    (every unmet distribution bound, and the failing seeds with theirs)."""

    passed: bool
    reason: str
    pass_rate: float


def judge_distribution(
    run_verdicts: dict[int, tuple[bool, str]],
    values: dict[str, list[float]],
    spec: DistributionSpec,
    percentile: Callable[[list[float], float], float],
) -> DistributionVerdict:
    """``run_verdicts``: seed -> (passed, reason) of each run; ``values``: metric -> its measured values over the
    seeds (None dropped); ``spec``: the scenario's ``[pass.distribution]``."""
    n = len(run_verdicts)
    passed_runs = sum(ok for ok, _ in run_verdicts.values())
    rate = passed_runs / n if n else 0.0
    need_rate = DEFAULT_MIN_PASS_RATE if spec.min_pass_rate is None else spec.min_pass_rate
    fails: list[str] = []
    if rate < need_rate:
        fails.append(f"{passed_runs}/{n} seeds pass (< {100 * need_rate:g} %)")
    bounds = [(spec.max_median, 50.0, "median", 1), (spec.min_median, 50.0, "median", -1),
              (spec.max_p90, 90.0, "p90", 1)]  # fmt: skip
    for table, q, label, sign in bounds:
        for metric, bound in table.items():
            vals = values.get(metric, [])
            if len(vals) < n:
                fails.append(f"{label} {metric} not measured on {n - len(vals)} of {n} seeds")
                continue
            v = percentile(vals, q)
            if sign * (v - bound) > 0:
                fails.append(f"{label} {metric} {v:.3g} {'>' if sign > 0 else '<'} {bound:g}")
    failing = [f"seed {s}: {why}" for s, (ok, why) in sorted(run_verdicts.items()) if not ok]
    if fails:
        reason = "; ".join(fails + failing)
    else:
        reason = "all criteria met" + (f" ({len(failing)} seed(s) fail: " + "; ".join(failing) + ")" if failing else "")
    return DistributionVerdict(not fails, reason, round(rate, 4))


@dataclass(frozen=True)
class GateMetric:
    """How the regression gate tests one metric: which way is worse, the scale of the paired differences
    (``log``: log((x + offset) / (baseline + offset)), a relative change; ``identity``: plain differences), and the
    effect-size floor a significant change must also exceed (relative for ``log``, in the metric's units otherwise).
    ``two_sided``: a change either way is a regression (physics figures: a change means the world changed)."""

    key: str
    scale: str  # "log" | "identity"
    floor: float
    worse: str = "higher"  # "higher" | "lower"
    offset: float = 0.0
    two_sided: bool = False
    estimator: bool = True  # a visual odometer replayed on the same inputs can change it (DR and the route it cannot)


@dataclass(frozen=True)
class GateBar:
    """The statistical regression gate (`bench suite --fast`): the current per-seed figures against the baseline's
    on the same seeds, each gated metric by the exact one-sided Wilcoxon signed-rank test, family-wise error held
    at ``alpha`` by Holm's procedure over every scenario x metric test of the run, plus the effect-size floor of
    each metric; the minimum detectable change is reported at ``power`` with the strictest Holm threshold."""

    alpha: float = 0.01
    power: float = 0.8
    min_pairs: int = 8
    metrics: tuple[GateMetric, ...] = (
        GateMetric("vo_error_pct", "log", floor=0.10, offset=0.05),
        GateMetric("vo_convergence_pct", "identity", floor=5.0, worse="lower"),
        GateMetric("dr_error_pct", "log", floor=0.10, offset=0.05, two_sided=True, estimator=False),
        GateMetric("goal_distance_m", "log", floor=0.25, offset=0.1, estimator=False),
    )


GATE = GateBar()


def regressed(p_value: float, threshold: float, effect: float, metric: GateMetric) -> bool:
    """A gated metric regressed: significant at its Holm threshold AND its median paired change (in the metric's
    scale, oriented so that positive is worse; absolute for two-sided metrics) reaches the effect-size floor."""
    size = abs(effect) if metric.two_sided else effect
    floor = math.log1p(metric.floor) if metric.scale == "log" else metric.floor
    return p_value <= threshold and size >= floor


def judge_globalloc(terrains: dict[str, dict], bar: GlobalLocBar = GLOBALLOC) -> tuple[bool, list[str]]:
    """``bench globalloc``'s verdict on one localiser's per-terrain summaries (``stops``, ``fixed``, ``success``,
    ``false_fixes``, ``median_error_m``, ``p90_error_m``, ``compute_s_median``, ``seeds``)."""
    reasons = []
    for name, b in terrains.items():
        if b["stops"] < bar.min_stops or len(b.get("seeds", [])) < bar.min_seeds:
            reasons.append(f"{name}: {b['stops']} stops over {len(b.get('seeds', []))} seeds "
                           f"(need >= {bar.min_stops} over >= {bar.min_seeds})")  # fmt: skip
        if b["false_fixes"] > bar.max_false_fixes:
            reasons.append(f"{name}: {b['false_fixes']} false fixes (> {bar.false_fix_m} m off; allowed 0)")
        if b["compute_s_median"] is not None and b["compute_s_median"] > bar.max_compute_s:
            reasons.append(f"{name}: median compute {b['compute_s_median']:.1f} s > {bar.max_compute_s} s")
        if name not in bar.fixed_terrains:
            continue
        frac = b["success"] / max(b["stops"], 1)
        if frac < bar.min_fixed_frac:
            reasons.append(f"{name}: {100 * frac:.0f} % of stops fixed within {bar.false_fix_m} m "
                           f"(< {100 * bar.min_fixed_frac:.0f} %)")  # fmt: skip
        for key, lim in (("median_error_m", bar.max_median_error_m), ("p90_error_m", bar.max_p90_error_m)):
            v = b[key]
            if v is None or v > lim:
                reasons.append(f"{name}: {key} {'not measured' if v is None else f'{v:.3f}'} (> {lim})")
    return not reasons, reasons
