"""The sol's drive budget: mission-clock charging, distance by mode, and the stop."""

from __future__ import annotations

import numpy as np
import pytest

from rover_sim.errors import ConfigError
from rover_sim.runtime.runner import Mission
from rover_sim.runtime.sol import BudgetSpent, SolBudget
from rover_sim.scenario.commands import SolSpec
from rover_sim.scenario.loading import load_scenario, scenario_from_dict
from rover_sim.sim.assembly import Sun
from rover_sim.world.clock import (
    AUTONAV_CYCLE_S,
    IMAGE_PAIR_ACQUIRE_S,
    SECONDS_PER_SOL,
    VO_STEP_COMPUTE_S,
    MissionClock,
)


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


def test_budgets_start_again_after_a_sleep_and_the_sols_are_listed() -> None:
    clock = MissionClock(10.0)
    sol = SolBudget(SolSpec(max_time_s=100.0, max_distance_m=5.0), clock)
    sol.on_tick(0.0, np.zeros(3), 0.0)
    clock.charge("driving", 60.0)
    sol.on_tick(60.0, np.array([3.0, 0.0, 0.0]), 3.0)
    clock.charge("computing", VO_STEP_COMPUTE_S)
    with pytest.raises(BudgetSpent, match="drive-time"):  # sol 1: 220 s of 100
        sol.on_tick(61.0, np.array([3.0, 0.0, 0.0]), 3.0)
    slept_s = sol.sleep(10.0)
    sol.on_tick(62.0, np.array([3.0, 0.0, 0.0]), 3.0)  # sol 2: its own budgets (the night is not drive time)
    clock.charge("driving", 60.0)
    sol.on_tick(122.0, np.array([7.0, 0.0, 0.0]), 7.0)  # 4 m of odometry in sol 2, 7 m in all: within 5 m a sol
    with pytest.raises(BudgetSpent, match="distance"):
        sol.on_tick(130.0, np.array([8.5, 0.0, 0.0]), 8.5)
    s = sol.summary()
    one, two = s["sols"]
    assert one["sol"] == 1 and one["stopped_by"] == "time" and two["stopped_by"] == "distance"
    assert one["time_by_activity_s"]["total_s"] == pytest.approx(60.0 + VO_STEP_COMPUTE_S)
    assert one["time_by_activity_s"]["sleeping_s"] == pytest.approx(slept_s, abs=1e-3)
    assert two["time_by_activity_s"] == {"driving_s": 60.0, "imaging_s": 0.0, "computing_s": 0.0, "total_s": 60.0,
                                         "sleeping_s": 0.0}  # fmt: skip
    assert one["distance_by_mode_m"]["blind"] == 3.0 and two["distance_by_mode_m"]["blind"] == 5.5
    assert one["odometry_m"] == 3.0 and two["odometry_m"] == 5.5
    assert two["start_local_solar_time_h"] == pytest.approx(10.0)
    assert s["time_by_activity_s"]["total_s"] == pytest.approx(120.0 + VO_STEP_COMPUTE_S)  # totals: no sleeping
    assert s["time_by_activity_s"]["sleeping_s"] == pytest.approx(slept_s, abs=1e-3)
    assert s["distance_by_mode_m"]["blind"] == 8.5 and s["stopped_by"] == "distance"


def _two_sol_dict(**sol: object) -> dict:
    return {
        "name": "two_sols",
        "terrain": {"size_m": [8, 8], "rocks": {"cover_fraction": 0.0}},
        "sol": {"max_time_s": 100.0, **sol},
        "commands": [{"type": "drive", "distance_m": 1.0}, {"type": "sleep"}, {"type": "drive", "distance_m": 1.0}],
    }


@pytest.mark.parametrize("wake", [24.0, -1.0, "ten"])
def test_a_bad_wake_time_is_refused_naming_the_field(wake: object) -> None:
    data = _two_sol_dict()
    data["commands"][1] = {"type": "sleep", "wake_local_solar_time_h": wake}
    with pytest.raises(ConfigError, match=r"commands\.1\.sleep\.wake_local_solar_time_h") as err:
        scenario_from_dict(data, "two.toml")
    assert "two.toml" in str(err.value) and "\n" not in str(err.value)


def test_a_sleep_needs_a_sol_and_a_moving_sun_must_be_up_at_the_wake_time() -> None:
    data = _two_sol_dict()
    del data["sol"]
    with pytest.raises(ConfigError, match=r"commands\.1: a 'sleep' command needs a \[sol\] table"):
        scenario_from_dict(data, "two.toml")
    dark = _two_sol_dict() | {"sun": {"latitude_deg": 0.0, "local_solar_time_h": 10.0}}
    dark["commands"][1] = {"type": "sleep", "wake_local_solar_time_h": 4.0}
    with pytest.raises(ConfigError, match="wake_local_solar_time_h = 4.0: the sun is"):
        scenario_from_dict(dark, "two.toml")
    sc = scenario_from_dict(_two_sol_dict(start_local_solar_time_h=9.5))
    assert sc.wake_local_solar_time_h(sc.commands[1]) == 9.5  # default: the time of day the drive started


# two sols on streamed 2 m tiles, the sun following the clock: a time budget cuts sol 1 (its third drive is skipped),
# the rover sleeps to 13:00 of the next sol and drives on
TWO_SOLS = {
    "name": "two_sols",
    "seed": 3,
    "terrain": {
        "cell_size_m": 0.05,
        "roughness": {"rms_m": 0.005, "correlation_length_m": 1.0},
        "rocks": {"cover_fraction": 0.0},
        "material": {"kind": "sand"},
        "streamed": {"tile_m": 2.0, "window_tiles": 3, "rock_slots": 16},
    },
    "appearance": {"texture_px_per_m": 20},
    "sun": {"latitude_deg": -14.57, "solar_longitude_deg": 0.0, "local_solar_time_h": 10.0},
    "start": {"x_m": 0.5},
    "nav": {"vo": False, "speed_m_s": 0.05, "image_noise": False},
    "sol": {"max_time_s": 60.0},
    "commands": [
        {"type": "drive", "distance_m": 2.0},
        {"type": "drive", "distance_m": 2.0},
        {"type": "drive", "distance_m": 2.0},
        {"type": "sleep", "wake_local_solar_time_h": 13.0},
        {"type": "drive", "distance_m": 2.0},
    ],
}


def test_a_two_sol_drive_sleeps_to_the_next_morning_with_fresh_budgets() -> None:
    sc = scenario_from_dict(TWO_SOLS)
    mission = Mission(sc)
    ticks: list[tuple[float, float, np.ndarray]] = []  # (sim time, local solar time, the observation's sun)
    clock = mission.world.clock
    assert clock is not None
    mission.tick_listeners.append(lambda obs, _truth: ticks.append(
        (obs.t_s, clock.local_solar_time_h, np.array(obs.sun_direction_world))))  # fmt: skip
    try:
        m = mission.run()
        mission.world.render("navcam")  # a render after the streamed window moved: lit by the sun of now
        r = mission.renderer.world
        np.testing.assert_allclose(r.model.light_dir[r.sun_id], mission.world.sun_direction_world, atol=1e-6)
    finally:
        mission.close()
    s = m.extra["sol"]
    one, two = s["sols"]
    assert one["stopped_by"] == "time" and 60.0 <= one["time_by_activity_s"]["total_s"] < 60.2
    assert any("command 2: drive skipped" in e for e in mission.events)
    assert two["stopped_by"] == "commands done" and two["time_by_activity_s"]["total_s"] < 60.0  # a fresh budget
    assert two["distance_by_mode_m"]["blind"] > 1.5 and one["distance_by_mode_m"]["blind"] > 2.5
    # the night: from the end of sol 1 to 13:00 next sol, charged as sleeping, not as drive time
    night_h = 24.0 + 13.0 - one["local_solar_time_h"]
    assert one["time_by_activity_s"]["sleeping_s"] == pytest.approx(night_h * SECONDS_PER_SOL / 24.0, abs=1.0)
    assert two["start_local_solar_time_h"] == pytest.approx(13.0)
    total = s["time_by_activity_s"]
    per_sol_s = one["time_by_activity_s"]["total_s"] + two["time_by_activity_s"]["total_s"]
    assert total["total_s"] == pytest.approx(per_sol_s)
    assert total["sleeping_s"] == one["time_by_activity_s"]["sleeping_s"]
    # no physics overnight: simulation time goes on one tick; the sun of the first tick after is the 13:00 sun
    k = next(i for i, (_, lst, _) in enumerate(ticks) if lst >= 12.99)
    assert ticks[k][0] - ticks[k - 1][0] == pytest.approx(0.125)
    az, el = sc.sun.azimuth_elevation_at(ticks[k][1])
    np.testing.assert_allclose(ticks[k][2], Sun(az, el).direction(), atol=1e-9)
    assert ticks[k][1] == pytest.approx(13.0, abs=0.01)
    moved_deg = np.degrees(np.arccos(np.clip(ticks[0][2] @ ticks[k][2], -1.0, 1.0)))
    assert moved_deg > 30.0  # 10:00 -> 13:00
    assert m.extra["streamed_terrain"]["recentres"] >= 2
