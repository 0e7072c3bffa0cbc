"""`bench traverse` judging against the issue-18 bars (the runs themselves are benchmarks, not tests)."""

from __future__ import annotations

from rover_sim.bench.traverse import CASES, judge

KM = {"name": "traverse_1km", "distance_m": 1004.0, "peak_rss_mb": 1500.0, "rss_100m_mb": 1200.0,
      "rss_end_mb": 1300.0, "recording_mb": 40.0, "realtime_factor": 18.0}  # fmt: skip


def test_km_case_bars() -> None:
    assert judge(KM) == (True, "")
    ok, why = judge(KM | {"rss_end_mb": 1400.0, "realtime_factor": 9.0})
    assert not ok and "RSS" in why and "real-time" in why
    assert not judge(KM | {"rss_100m_mb": None})[0]  # never reached 100 m: no baseline, no pass


def test_sol_case_bars() -> None:
    spirit = {"name": "spirit_plains_sol", "onboard_goal_distance_m": 0.4, "tall_rock_contacts": 0, "dr_error_pct": 3.2}
    assert judge(spirit)[0]
    assert not judge(spirit | {"dr_error_pct": 0.5})[0]
    assert not judge(spirit | {"tall_rock_contacts": 3})[0]
    assert judge({"name": "opportunity_record_sol", "distance_m": 212.0})[0]
    assert not judge({"name": "opportunity_record_sol", "distance_m": 150.0})[0]
    assert all(p.is_file() for p in CASES.values())
