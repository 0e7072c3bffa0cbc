"""The moving sun: Mars ephemeris and shadows that move between pairs hours apart."""

from __future__ import annotations

import numpy as np
import pytest

from rover_sim.errors import ConfigError
from rover_sim.scenario.loading import scenario_from_dict
from rover_sim.sim.ephemeris import solar_declination_deg, sun_azimuth_elevation_deg
from rover_sim.world.clock import SECONDS_PER_SOL
from rover_sim.world.world import World

MARS_HOUR_S = SECONDS_PER_SOL / 24.0


@pytest.mark.parametrize(("lat", "ls"), [(-14.57, 0.0), (-1.95, 90.0), (18.4, 251.0), (-60.0, 270.0)])
def test_noon_elevation_is_90_minus_latitude_minus_declination(lat, ls):
    az, el = sun_azimuth_elevation_deg(lat, ls, 12.0)
    decl = solar_declination_deg(ls)
    assert el == pytest.approx(90.0 - abs(lat - decl), abs=1e-6)
    assert abs(abs(az) - 90.0) < 1e-6  # due north (+y) or due south (-y) at local noon


def test_declination_at_the_solstices_and_the_morning_sun_in_the_east():
    assert solar_declination_deg(90.0) == pytest.approx(25.44, abs=0.01)  # 25.19 deg obliquity + 0.25 correction
    assert solar_declination_deg(270.0) == pytest.approx(-25.44, abs=0.01)
    assert solar_declination_deg(0.0) == 0.0
    az, el = sun_azimuth_elevation_deg(0.0, 0.0, 6.0)  # equinox at the equator: rises due east at 6 h
    assert az == pytest.approx(0.0, abs=1e-6) and el == pytest.approx(0.0, abs=1e-6)
    az, el = sun_azimuth_elevation_deg(0.0, 0.0, 15.0)  # 45 deg west of the zenith at 15 h
    assert abs(az) == pytest.approx(180.0, abs=1e-6) and el == pytest.approx(45.0, abs=1e-6)


def test_a_time_with_the_sun_below_the_horizon_is_refused():
    with pytest.raises((ConfigError, ValueError), match="local_solar_time_h"):
        scenario_from_dict(FIELD | {"sun": {"latitude_deg": 0.0, "local_solar_time_h": 5.0}})


FIELD = {
    "name": "moving_sun_probe",
    "terrain": {
        "size_m": [8, 8],
        "cell_size_m": 0.05,
        "roughness": {"rms_m": 0.002, "correlation_length_m": 1.0},
        "rocks": {"cover_fraction": 0.0},
    },
    "appearance": {"fine_soil": True},
    "commands": [{"type": "drive", "distance_m": 0.1}],
    "nav": {"image_noise": False, "mast_tilt_deg": -50},
}


def _shadow_mask(world: World) -> np.ndarray:
    """Pixels of a pair taken now that the rover's shadow darkens (the same view rendered without shadows)."""
    r = world.renderer
    lit = world.render("navcam").left.astype(float)
    r.shadows = False
    unlit = r.render_grey("navcam_left").astype(float)
    r.shadows = True
    return unlit - lit > 8


def test_the_rovers_shadow_moves_between_pairs_two_hours_apart():
    sun = {"latitude_deg": -14.57, "solar_longitude_deg": 0.0, "local_solar_time_h": 14.0}
    world = World(scenario_from_dict(FIELD | {"sun": sun}))  # rover faces +x (east): the afternoon shadow is ahead
    try:
        early = _shadow_mask(world)
        dir_early = world.sun_direction_world.copy()
        world.charge("computing", 2.0 * MARS_HOUR_S)
        late = _shadow_mask(world)
        assert world.clock is not None and world.clock.local_solar_time_h == pytest.approx(16.0, abs=0.01)
        assert np.degrees(np.arccos(np.clip(dir_early @ world.sun_direction_world, -1, 1))) > 20.0
    finally:
        world.close()
    assert early.sum() > 200 and late.sum() > 200
    assert late.sum() > 1.3 * early.sum()  # the sun is lower: a longer shadow
    rows_early, rows_late = np.nonzero(early)[0], np.nonzero(late)[0]
    assert abs(rows_late.mean() - rows_early.mean()) > 5.0  # and it lies elsewhere in the image
    assert (early & late).sum() < 0.8 * early.sum()


def test_the_soils_micro_relief_is_reshaded_when_the_sun_has_moved():
    sun = {"latitude_deg": -14.57, "solar_longitude_deg": 0.0, "local_solar_time_h": 14.0}
    sc = scenario_from_dict(FIELD | {"sun": sun, "appearance": {"regolith": "multiscale"}})
    world = World(sc)
    try:
        m = world.renderer.world.model
        tid = m.texture("terrain_albedo").id
        span = slice(int(m.tex_adr[tid]), int(m.tex_adr[tid]) + 3 * int(m.tex_width[tid] * m.tex_height[tid]))
        before = m.tex_data[span].copy()
        world.render("navcam")  # the sun has not moved: no re-bake
        np.testing.assert_array_equal(m.tex_data[span], before)
        world.charge("computing", 1.0 * MARS_HOUR_S)
        world.render("navcam")
        changed = np.abs(m.tex_data[span].astype(int) - before).mean()
    finally:
        world.close()
    assert changed > 1.0  # grey levels, mean over the texture


def test_without_a_time_of_day_the_sun_stays_fixed_and_there_is_no_clock():
    world = World(scenario_from_dict(FIELD | {"sun": {"azimuth_deg": 100.0, "elevation_deg": 30.0}}))
    try:
        m = world.renderer.world.model
        before = m.light_dir[world.renderer.world.sun_id].copy()
        world.render("navcam")
        np.testing.assert_array_equal(m.light_dir[world.renderer.world.sun_id], before)
        np.testing.assert_allclose(world.sun_direction_world, before / np.linalg.norm(before), atol=1e-6)
        assert world.clock is None and world.clock_summary() is None
    finally:
        world.close()
