"""The sol's drive budget (issue #18): mission-clock charging, distance by mode, and the stop."""

from __future__ import annotations

import numpy as np
import pytest

from rover_sim.mission.clock import AUTONAV_CYCLE_S, IMAGE_PAIR_ACQUIRE_S, VO_STEP_COMPUTE_S, MissionClock
from rover_sim.mission.scenario import SolSpec, load_scenario
from rover_sim.mission.sol import BudgetSpent, SolBudget


def test_distance_splits_by_mode_on_the_worlds_clock() -> None:
    clock = MissionClock(10.0)
    sol = SolBudget(SolSpec(max_time_s=10_000.0), clock)
    sol.on_tick(0.0, np.zeros(3), 0.0)
    sol.on_tick(10.0, np.array([0.4, 0.3, 0.0]), 0.5)  # 0.5 m blind
    sol.mode = "autonav"
    clock.charge("computing", AUTONAV_CYCLE_S - IMAGE_PAIR_ACQUIRE_S)  # what the pipeline charges per cycle
    sol.on_tick(20.0, np.array([0.4, 1.3, 0.0]), 1.5)
    s = sol.summary()
    assert s["time_by_activity_s"]["computing_s"] == pytest.approx(AUTONAV_CYCLE_S - IMAGE_PAIR_ACQUIRE_S)
    assert s["distance_by_mode_m"] == {"blind": 0.5, "blind_vo": 0.0, "autonav": 1.0}
    assert s["stopped_by"] == "commands done"


def test_time_and_distance_budgets_stop_the_drive() -> None:
    clock = MissionClock(10.0)
    sol = SolBudget(SolSpec(max_time_s=100.0), clock)
    sol.on_tick(0.0, np.zeros(3), 0.0)
    clock.charge("computing", VO_STEP_COMPUTE_S)  # 160 s of computing: over the budget at the next tick
    with pytest.raises(BudgetSpent, match="drive-time"):
        sol.on_tick(1.0, np.zeros(3), 0.0)
    assert sol.summary()["stopped_by"] == "time"
    far = SolBudget(SolSpec(max_time_s=1e4, max_distance_m=5.0), MissionClock(10.0))
    far.on_tick(0.0, np.zeros(3), 4.9)
    with pytest.raises(BudgetSpent, match="distance"):
        far.on_tick(1.0, np.zeros(3), 5.0)


@pytest.mark.parametrize("name", ["spirit_plains_sol", "opportunity_record_sol"])
def test_sol_scenarios_are_streamed_and_budgeted(name: str) -> None:
    sc = load_scenario(name)
    assert sc.terrain.streamed is not None and sc.sol is not None and not sc.sol.benchmark_only
    assert "streamed" in sc.resolved_dict()["terrain"]
    plain = load_scenario("wopmay").resolved_dict()
    assert "streamed" not in plain["terrain"] and "sol" not in plain  # whole-site scenario.json unchanged
