"""Figures over seeds: summaries, the exact signed-rank test, Holm, the power analysis, seed sets and the gate."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats as sps

from rover_sim.bench import gate, stats
from rover_sim.bench.seeds import parse_seeds, seed_set
from rover_sim.errors import ConfigError
from rover_sim.runtime import acceptance
from rover_sim.scenario.criteria import DistributionSpec


@pytest.mark.parametrize("n", [5, 8, 12])
def test_signed_rank_p_matches_scipy_exact(n):
    rng = np.random.default_rng(n)
    for _ in range(20):
        d = rng.normal(0.2, 1.0, n)
        for alt in ("greater", "less", "two-sided"):
            want = sps.wilcoxon(d, alternative=alt, method="exact").pvalue
            assert stats.signed_rank_p(d, alt) == pytest.approx(want, rel=1e-9)


def test_signed_rank_p_drops_zeros_and_handles_ties():
    assert stats.signed_rank_p(np.zeros(12)) == 1.0  # identical runs: nothing to test
    assert stats.signed_rank_p(np.ones(12)) == pytest.approx(2.0**-12)  # every pair worse, all tied
    assert stats.min_attainable_p(12) == 2.0**-12 and stats.min_attainable_p(4) == 1 / 16


def test_holm_steps_down_and_stops_at_the_first_acceptance():
    rejected, thr = stats.holm([0.001, 0.04, 0.0001, 0.003], alpha=0.01)
    assert thr == pytest.approx([0.01 / 3, 0.01 / 1, 0.01 / 4, 0.01 / 2])
    assert rejected == [True, False, True, True]
    assert stats.holm([0.02, 0.0001], 0.01)[0] == [False, True]


def test_summary_keeps_missing_seeds_and_picks_the_worst_by_direction():
    s = stats.summarize({1: 0.5, 2: None, 3: 2.0, 4: 0.7})
    assert (s.median, s.worst, s.n) == (0.7, 2.0, 3) and s.per_seed[2] is None
    lo, hi = s.ci90
    assert 0.5 <= lo <= s.median <= hi <= 2.0
    assert stats.summarize({1: 90.0, 2: 100.0}, higher_is_better=True).worst == 90.0
    assert stats.summarize({1: None}).median is None
    assert stats.summarize({1: 1.0, 2: 3.0}) == stats.summarize({1: 1.0, 2: 3.0})  # seeded bootstrap


def test_min_detectable_shift_grows_with_the_spread_and_needs_enough_pairs():
    rng = np.random.default_rng(0)
    narrow = stats.min_detectable_shift(rng.normal(0, 0.02, 12), alpha=0.001)
    wide = stats.min_detectable_shift(rng.normal(0, 0.2, 12), alpha=0.001)
    assert 0 < narrow < wide
    assert stats.min_detectable_shift(rng.normal(0, 0.02, 4), alpha=0.01) is None  # 2**-4 > 1 %: never rejects


def test_seed_sets_are_disjoint_and_parsed():
    sets = [seed_set(n) for n in ("tuning", "published", "gate")]
    for i, a in enumerate(sets):
        for b in sets[i + 1 :]:
            assert a.last < b.first or b.last < a.first
    assert parse_seeds(None, "gate", 12).values == tuple(range(seed_set("gate").first, seed_set("gate").first + 12))
    assert parse_seeds("3", "published", 8).seed_set == "published"
    assert parse_seeds("100-102", "gate", 8).values == (100, 101, 102)
    assert parse_seeds("5,1000", "gate", 8).seed_set == "custom"
    for bad in ("0", "x", "3-1", "1,1", "-2"):
        with pytest.raises(ConfigError, match="--seeds"):
            parse_seeds(bad, "gate", 8)


def test_distribution_verdict_counts_seeds_and_bounds():
    verdicts = {s: (s != 3, "VO error 1.2 % > 1 %" if s == 3 else "all criteria met") for s in range(8)}
    vals = {"vo_error_pct": [0.5, 0.6, 0.7, 1.2, 0.4, 0.5, 0.9, 0.8]}
    pct = stats.percentile
    ok = acceptance.judge_distribution(verdicts, vals, DistributionSpec(min_pass_rate=0.75), pct)
    assert ok.passed and ok.pass_rate == 0.875 and "seed 3" in ok.reason
    strict = acceptance.judge_distribution(verdicts, vals, DistributionSpec(min_pass_rate=1.0), pct)
    assert not strict.passed and "7/8 seeds pass" in strict.reason
    bound = DistributionSpec(max_median={"vo_error_pct": 0.6}, max_p90={"vo_error_pct": 2.0})
    v = acceptance.judge_distribution(verdicts, vals, bound, pct)
    assert not v.passed and "median vo_error_pct" in v.reason and "p90" not in v.reason


def _baseline(values, perturbed, seeds=range(200, 212)):
    return gate.Baseline("flight", tuple(seeds), {}, {"size": 1e-6, "seed": 1},
                         {"s": {"vo_error_pct": dict(zip(seeds, values, strict=True))}},
                         {"s": {"vo_error_pct": dict(zip(seeds, perturbed, strict=True))}})  # fmt: skip


def test_gate_passes_the_spread_and_flags_a_worse_estimator(tmp_path):
    rng = np.random.default_rng(1)
    base = np.exp(rng.normal(np.log(0.6), 0.4, 12))
    spread = base * np.exp(rng.normal(0, 0.05, 12))
    b = _baseline(base, spread)
    gate.save_baseline(b, tmp_path / "b.json")
    b = gate.load_baseline(tmp_path / "b.json")
    seeds = list(b.seeds)
    same = gate.compare({"s": {"vo_error_pct": dict(zip(seeds, spread, strict=True))}}, b)["s"]["vo_error_pct"]
    assert not same.regressed and same.min_detectable_rel is not None and same.min_detectable_rel < 0.2
    worse = gate.compare({"s": {"vo_error_pct": dict(zip(seeds, base * 1.5, strict=True))}}, b)["s"]["vo_error_pct"]
    assert worse.regressed and worse.p_value <= worse.threshold and worse.delta_median_rel == pytest.approx(0.5, 0.2)
    # a significant but tiny change stays under the effect-size floor
    tiny = gate.compare({"s": {"vo_error_pct": dict(zip(seeds, base * 1.03 + 0.01, strict=True))}}, b)
    assert not tiny["s"]["vo_error_pct"].regressed


def test_gate_refuses_too_few_seeds_and_old_baselines(tmp_path):
    with pytest.raises(ConfigError, match="--seeds"):
        gate.check_power(4, 6)
    gate.check_power(12, 18)
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"wopmay": {"vo_error_pct": 0.5}}))
    with pytest.raises(ConfigError, match="update-baseline"):
        gate.load_baseline(old)


def test_regressed_needs_significance_and_the_floor():
    m = acceptance.GateMetric("vo_error_pct", "log", floor=0.10)
    assert acceptance.regressed(0.0001, 0.001, math.log(1.2), m)
    assert not acceptance.regressed(0.01, 0.001, math.log(1.2), m)
    assert not acceptance.regressed(0.0001, 0.001, math.log(1.05), m)
    two = acceptance.GateMetric("dr_error_pct", "log", floor=0.10, two_sided=True)
    assert acceptance.regressed(0.0001, 0.001, -math.log(1.3), two)


def test_report_states_seeds_profile_cell_size_and_machine():
    from rover_sim.bench.report import markdown

    metric = {"median": 0.5, "mean": 0.6, "ci90": [0.4, 0.7], "worst": 1.0, "per_seed": {"100": 0.5}}
    data = {"seeds": list(range(100, 108)), "seed_set": "published", "perturb": None,
            "environment": {"cpu": "Test CPU", "cpus": 2, "python": "3.11", "packages": {"mujoco": "4.0.0"},
                            "commit": "abc"},
            "profiles": {"flight": {"scenarios": {"wopmay": {
                "pass_rate": 1.0, "passed": True, "reason": "all criteria met", "criteria": "VO <= 2 %",
                "cell_size_m": 0.04, "metrics": {"vo_error_pct": metric}}}}}}  # fmt: skip
    md = markdown(data)
    assert "8 seeds (100–107, published set)" in md and "Test CPU" in md and "commit abc" in md
    assert "**built-in stack, flight profile**" in md and "| wopmay | 0.04 | 1.00 |" in md
    assert "0.50 [0.40, 0.70]" in md
