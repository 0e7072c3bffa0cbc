import pytest

from rover_sim.world.clock import SECONDS_PER_SOL, MissionClock


def test_clock_accumulates_by_activity_and_wraps_the_time_of_day():
    c = MissionClock(start_local_solar_time_h=23.0)
    c.charge("driving", 100.0)
    c.charge("computing", 160.0)
    c.charge("imaging", 10.0)
    assert c.elapsed_s == pytest.approx(270.0)
    assert c.summary()["computing_s"] == pytest.approx(160.0)
    c.charge("driving", 2.0 * SECONDS_PER_SOL / 24.0)  # two Mars hours
    assert c.local_solar_time_h == pytest.approx((23.0 + 2.0 + 24.0 * 270.0 / SECONDS_PER_SOL) % 24.0)
    assert c.local_solar_time_h < 2.0


@pytest.mark.parametrize("bad", [("napping", 1.0), ("driving", -1.0), ("driving", float("nan"))])
def test_clock_refuses_unknown_activities_and_negative_time(bad):
    with pytest.raises(ValueError):
        MissionClock().charge(*bad)


def test_sleep_runs_to_the_next_mornings_wake_time_and_is_not_drive_time():
    hour_s = SECONDS_PER_SOL / 24.0
    c = MissionClock(start_local_solar_time_h=10.0)
    c.charge("driving", 4.0 * hour_s)  # the drive ends at 14:00
    slept = c.sleep_until(10.0)
    assert slept == pytest.approx(20.0 * hour_s)
    assert c.local_solar_time_h == pytest.approx(10.0) and c.sol_index == 1
    assert c.drive_s == pytest.approx(4.0 * hour_s) and c.elapsed_s == pytest.approx(24.0 * hour_s)
    s = c.summary()
    assert s["total_s"] == pytest.approx(4.0 * hour_s) and s["sleeping_s"] == pytest.approx(20.0 * hour_s)
    # a wake time earlier in the day than the sleep, past midnight, or later: always the next sol's morning
    c.charge("computing", 14.5 * hour_s)  # 00:30 of sol 2: the drive ran past midnight
    assert c.local_solar_time_h == pytest.approx(0.5) and c.sol_index == 2
    assert c.sleep_until(9.0) / hour_s == pytest.approx(24.0 + 8.5)  # wakes after the next midnight
    early = MissionClock(start_local_solar_time_h=8.0)
    assert early.sleep_until(9.5) / hour_s == pytest.approx(25.5)  # not 1.5 h later on the same morning
    midnight = MissionClock(start_local_solar_time_h=10.0)
    midnight.sleep_until(0.0)
    assert midnight.sleep_until(0.0) / hour_s == pytest.approx(24.0)  # a wake at 0 h counts as the new sol


def test_sleep_refuses_a_wake_time_outside_the_day():
    with pytest.raises(ValueError, match="wake_local_solar_time_h"):
        MissionClock().sleep_until(24.0)
