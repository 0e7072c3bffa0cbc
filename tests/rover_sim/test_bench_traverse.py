"""`bench traverse` judging against its bars (rover_sim.runtime.acceptance.bars.TraverseBar; the runs themselves are
benchmarks, not tests)."""

from __future__ import annotations

from rover_sim.bench.traverse import CASES
from rover_sim.runtime.acceptance.bars import traverse_verdict

KM = {"name": "traverse_1km", "distance_m": 1004.0, "peak_rss_mb": 1500.0, "rss_100m_mb": 1200.0,
      "rss_end_mb": 1300.0, "recording_mb": 40.0, "realtime_factor": 18.0}  # fmt: skip


def test_km_case_bars() -> None:
    v = traverse_verdict(KM)
    assert v.passed and v.reasons == []
    bad = traverse_verdict(KM | {"rss_end_mb": 1400.0, "realtime_factor": 9.0})
    assert not bad.passed and "RSS" in bad.reason and "real-time" in bad.reason
    assert not traverse_verdict(KM | {"rss_100m_mb": None}).passed  # never reached 100 m: no baseline, no pass


def test_sol_case_bars() -> None:
    spirit = {"name": "spirit_plains_sol", "onboard_goal_distance_m": 0.4, "tall_rock_contacts": 0, "dr_error_pct": 3.2}
    assert traverse_verdict(spirit).passed
    assert not traverse_verdict(spirit | {"dr_error_pct": 0.5}).passed
    assert not traverse_verdict(spirit | {"tall_rock_contacts": 3}).passed
    assert traverse_verdict({"name": "opportunity_record_sol", "distance_m": 212.0}).passed
    assert not traverse_verdict({"name": "opportunity_record_sol", "distance_m": 150.0}).passed
    assert all(p.is_file() for p in CASES.values())
