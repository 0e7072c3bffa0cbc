"""The one judge: every pass criterion and benchmark bar, and the verdicts built from them.

A scenario's own criteria live in its ``[pass]`` table (:class:`rover_sim.scenario.criteria.PassSpec`) and are
judged by :func:`scenario_verdict`; over seeds by :func:`judge_distribution`; the statistical regression gate's
rules are :data:`GATE`. Each benchmark's bars are the typed constants of :mod:`rover_sim.runtime.acceptance.bars`,
judged by its ``*_verdict`` function there. A :class:`Verdict` holds every check (name, pass, the measured value, the
bar, and why it failed); the console tables, the JSON's ``passed`` / ``reasons``, the JUnit cases
(:mod:`rover_sim.bench.junit_cases`) and the exit status are all derived from it, in this package and nowhere else.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from rover_sim.runtime.evaluator import FALSE_POSITIVE_FRACTION as EVAL_FALSE_POSITIVE_FRACTION
from rover_sim.runtime.evaluator import FALSE_POSITIVE_M as EVAL_FALSE_POSITIVE_M
from rover_sim.runtime.evaluator import MIN_DISTANCE_FOR_PCT_M, TEXTURED_VIEW_FRAC, Metrics
from rover_sim.scenario.commands import KeepOut
from rover_sim.scenario.criteria import DistributionSpec, PassSpec

TALL_ROCK_M = 0.25  # GESTALT must avoid touching rocks at least this tall (wheel or body)
FALSE_POSITIVE_M = EVAL_FALSE_POSITIVE_M  # false positive: error > max(this, FALSE_POSITIVE_FRACTION x step)
FALSE_POSITIVE_FRACTION = EVAL_FALSE_POSITIVE_FRACTION
RUN_DID_NOT_COMPLETE = "run did not complete"


@dataclass(frozen=True)
class Check:
    """One bar: ``why`` is the unmet bar with the measured value (empty when it passed)."""

    name: str
    passed: bool
    why: str = ""
    measured: str = ""
    bar: str = ""

    def cell(self) -> str:
        """A console table's ok cell: ``yes`` or ``NO: why``."""
        return pass_cell(self.passed, self.why or self.name)


@dataclass(frozen=True)
class Verdict:
    """Every check of one run or benchmark; ``error``: it did not run to completion (a run error, interrupted)."""

    checks: tuple[Check, ...] = ()
    error: str | None = None

    @property
    def passed(self) -> bool:
        return self.error is None and all(c.passed for c in self.checks)

    @property
    def reasons(self) -> list[str]:
        return ([self.error] if self.error else []) + [c.why or c.name for c in self.checks if not c.passed]

    @property
    def reason(self) -> str:
        return "; ".join(self.reasons) or "all criteria met"

    def cell(self) -> str:
        """A console table's pass cell: ``yes`` or ``NO: <reasons>``."""
        return pass_cell(self.passed, self.reason)


def check(name: str, ok: bool, why: str, measured: str = "", bar: str = "") -> Check:
    return Check(name, bool(ok), "" if ok else why, measured, bar)


def at_least(name: str, value: float | None, bar: float, fmt: str = "{:g}", op: str = ">=") -> Check:
    """``value >= bar`` (``op="<="``: at most); ``fmt`` formats both, with their unit; None (not measured) fails."""
    text, bar_text = "not measured" if value is None else fmt.format(value), f"{op} {fmt.format(bar)}"
    ok = value is not None and (value >= bar if op == ">=" else value <= bar)
    return check(name, ok, f"{name} {text} (need {bar_text})", text, bar_text)


def at_most(name: str, value: float | None, bar: float, fmt: str = "{:g}") -> Check:
    return at_least(name, value, bar, fmt, "<=")


def pass_cell(passed: bool, reason: str) -> str:
    """``yes``, or ``NO: <reason>`` (every failing console row says why)."""
    return "yes" if passed else f"NO: {reason}"


DESCRIBE = (  # PassSpec field -> how describe() words it
    ("max_vo_error_pct", "VO <= {:g} %"), ("min_dr_error_pct", "DR >= {:g} %"), ("max_dr_error_pct", "DR <= {:g} %"),
    ("min_vo_convergence_pct", "convergence >= {:g} %"),
    ("min_vo_textured_convergence_pct", "convergence on textured steps >= {:g} %"),
    ("min_max_slip_pct", "slip >= {:g} %"), ("max_max_slip_pct", "slip <= {:g} %"),
    ("max_false_positives", "{} false positives"), ("expect_halt", "{} halt"), ("goal_within_m", "goal within {:g} m"),
    ("max_site_error_vs_dr", "site error <= {:g} x DR's"), ("max_body_collisions", "<= {} collisions"),
    ("min_final_sinkage_m", "final sinkage >= {:g} m"), ("max_final_sinkage_m", "final sinkage <= {:g} m"),
    ("min_final_slip_pct", "final slip >= {:g} %"),
)  # fmt: skip


def describe(p: PassSpec) -> str:
    """The scenario's criteria as one line (for benchmark tables)."""
    parts = [fmt.format(v) for key, fmt in DESCRIBE if (v := getattr(p, key)) is not None]
    return ", ".join(parts) or "runs to completion"


def judge(
    m: Metrics, p: PassSpec, *, error: str | None, keep_out_info: dict | None, keep_out: list[KeepOut]
) -> tuple[bool, str]:
    """Pass/fail of one run and the reason naming every unmet bound (:func:`scenario_verdict`)."""
    v = scenario_verdict(m, p, error=error, keep_out_info=keep_out_info, keep_out=keep_out)
    return v.passed, v.reason


def scenario_verdict(
    m: Metrics, p: PassSpec, *, error: str | None, keep_out_info: dict | None, keep_out: list[KeepOut]
) -> Verdict:
    """One run against its scenario's ``[pass]`` criteria: one check per unmet bound, naming it."""
    if error:
        return Verdict(error=f"{RUN_DID_NOT_COMPLETE}: {error}")
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
        conv = m.vo_convergence_pct
        need(conv is not None and conv >= p.min_vo_convergence_pct,
             f"VO convergence {conv} % < {p.min_vo_convergence_pct} %")  # fmt: skip
    if p.min_vo_textured_convergence_pct is not None:
        conv, bar = m.vo_textured_convergence_pct, p.min_vo_textured_convergence_pct
        need(conv is not None, f"VO convergence on textured steps not measured: no step had >= "
             f"{100 * TEXTURED_VIEW_FRAC:.0f} % of its view on texture")  # fmt: skip
        need(conv is None or conv >= bar, f"VO convergence on textured steps {conv} % "
             f"({m.vo_textured_accepted}/{m.vo_textured_steps}) < {bar} %")  # fmt: skip
    if p.min_max_slip_pct is not None:
        need(m.max_slip_pct >= p.min_max_slip_pct, f"max slip {m.max_slip_pct} % < {p.min_max_slip_pct} %")
    if p.max_max_slip_pct is not None:
        need(m.max_slip_pct <= p.max_max_slip_pct, f"max slip {m.max_slip_pct} % > {p.max_max_slip_pct} %")
    if p.max_false_positives is not None:
        need(m.false_positives <= p.max_false_positives, f"{m.false_positives} VO false positives > "
             f"{p.max_false_positives}")  # fmt: skip
    if p.expect_halt is not None:
        need(m.halted == p.expect_halt, f"expected a {p.expect_halt} halt, got {m.halted}")
    elif m.halted is not None:
        fails.append(f"unexpected {m.halted} halt")
    if p.expect_dead_reckoning_clear:
        d = None if keep_out_info is None else keep_out_info["dead_reckoning_distance_m"]
        need(d is not None and d > keep_out_info["onboard_distance_m"] + 0.1 and any(d >= z.radius_m for z in keep_out),
             "dead reckoning did not believe the rover clear at the keep-out halt")  # fmt: skip
    if p.goal_within_m is not None:
        g = m.goal_distance_m
        need(g is not None and g <= p.goal_within_m, f"ended {g} m from the goal (> {p.goal_within_m} m)")
    if p.max_site_error_vs_dr is not None:
        _judge_sites(m.extra.get("sites"), p.max_site_error_vs_dr, need)
    if p.max_body_collisions is not None:
        need(m.body_collisions <= p.max_body_collisions, f"{m.body_collisions} body-collision ticks")
        need(m.tall_rock_contacts <= p.max_body_collisions,
             f"{m.tall_rock_contacts} ticks touching rocks taller than {TALL_ROCK_M} m")  # fmt: skip
    if p.judges_wheels():
        _judge_wheels(m.extra.get("wheels"), p, need)
    return Verdict(tuple(Check(text, False, text) for text in fails))


def _judge_sites(sites: dict | None, factor: float, need: Callable[[bool, str], None]) -> None:
    """Localisation (rock_localization): the onboard pose's mean horizontal error at the sites (goto ends) against
    dead reckoning's; dead reckoning alone (VO off) scores exactly 1."""
    if not sites:
        need(False, "site errors not measured: no goto site")
        return
    on, dr = sites["onboard_mean_m"], sites["dead_reckoning_mean_m"]
    need(on <= factor * dr, f"mean site error {on} m > {factor:g} x dead reckoning's {dr} m")


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
        GateMetric("vo_rotation_error_deg_per_m", "log", floor=0.10, offset=0.01),
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
