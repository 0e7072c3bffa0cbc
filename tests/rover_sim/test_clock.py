import pytest

from rover_sim.mission.clock import SECONDS_PER_SOL, MissionClock


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


@pytest.mark.parametrize("bad", [("sleeping", 1.0), ("driving", -1.0), ("driving", float("nan"))])
def test_clock_refuses_unknown_activities_and_negative_time(bad):
    with pytest.raises(ValueError):
        MissionClock().charge(*bad)
