"""Where the sun is in a Mars site's sky: direction from latitude, season (Ls) and local true solar time.

Allison & McEwen (2000), "A post-Pathfinder evaluation of areocentric solar coordinates with improved timing
recipes for Mars seasonal/diurnal climate studies", Planet. Space Sci. 48, 215-235:

* solar declination from the areocentric solar longitude ``Ls`` (their eq. 7)::

      decl = asin(0.42565 sin Ls) + 0.25 deg * sin Ls

* the hour angle from local *true* solar time (LTST, the sun's own clock: 12 h is local noon), 15 deg per Mars
  hour: ``H = 15 deg * (LTST - 12)``;
* elevation and azimuth by the standard spherical-astronomy relations (the same on any planet)::

      sin el = sin lat sin decl + cos lat cos decl cos H
      azimuth (from north, through east) = atan2(-cos decl sin H, cos lat sin decl - sin lat cos decl cos H)

Accuracy: given LTST directly, the declination formula is within about 0.1 deg of the full ephemeris and the
direction within about 0.2 deg; refraction (the thin, dusty atmosphere: under 0.1 deg above 10 deg elevation) and
the solar disc's 0.35 deg width are ignored. Converting a clock time (LMST) to LTST would need Mars' equation of
time (up to about 50 minutes); the scenarios give LTST directly so that step is not needed.

Site frame (as :class:`rover_sim.sim.assembly.Sun`): +x east, +y north, +z up; azimuth from +x toward +y.
"""

from __future__ import annotations

import math

MARS_OBLIQUITY_SIN = 0.42565  # sin(25.19 deg): Allison & McEwen (2000), eq. 7
DECLINATION_CORRECTION_DEG = 0.25
DEG_PER_HOUR = 15.0  # hour angle per Mars hour (1/24 sol)


def solar_declination_deg(solar_longitude_deg: float) -> float:
    """Solar declination from the areocentric solar longitude ``Ls`` (Allison & McEwen 2000, eq. 7)."""
    ls = math.radians(solar_longitude_deg)
    return math.degrees(math.asin(MARS_OBLIQUITY_SIN * math.sin(ls))) + DECLINATION_CORRECTION_DEG * math.sin(ls)


def sun_azimuth_elevation_deg(
    latitude_deg: float, solar_longitude_deg: float, local_solar_time_h: float
) -> tuple[float, float]:
    """The sun's (azimuth, elevation) in degrees in the site frame (azimuth from +x east toward +y north)."""
    if not -90.0 <= latitude_deg <= 90.0:
        raise ValueError(f"latitude_deg must be in [-90, 90], got {latitude_deg}")
    lat = math.radians(latitude_deg)
    dec = math.radians(solar_declination_deg(solar_longitude_deg))
    h = math.radians(DEG_PER_HOUR * (local_solar_time_h - 12.0))
    sin_el = math.sin(lat) * math.sin(dec) + math.cos(lat) * math.cos(dec) * math.cos(h)
    el = math.asin(max(-1.0, min(1.0, sin_el)))
    az_from_north = math.atan2(
        -math.cos(dec) * math.sin(h), math.cos(lat) * math.sin(dec) - math.sin(lat) * math.cos(dec) * math.cos(h)
    )
    az_site = (90.0 - math.degrees(az_from_north)) % 360.0
    if az_site > 180.0:
        az_site -= 360.0
    return az_site, math.degrees(el)
