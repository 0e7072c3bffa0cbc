"""``[sensors.odometry]``: odometry and attitude errors; every term a seeded 1-sigma draw.

Where each error arises (:mod:`rover_sim.sim.sensors` applies them; the onboard geometry stays nominal):

* ``wheel_radius_error_pct``: each wheel's effective rolling radius differs from the nominal 0.125 m that the
  onboard odometry uses (tread wear, grouser penetration, tyre build tolerance). The encoder reports the true
  rotation; the truth rolls ``r_eff * angle``. Simulated as an encoder scale of ``1 / (1 + e)`` per wheel, which
  gives the onboard odometry exactly the distance error a radius error ``e`` gives. No published MER number: an
  assumption (1 %).
* ``steer_offset_deg``: a zero offset of each steering sensor (4 steerable corner wheels): the wheel points where
  the actuator put it, the sensor reads it off by a constant. Assumption (0.5 deg), no published MER number.
* ``imu_misalignment_mrad``: a small rotation of the IMU axes against the rover body frame (mounting), per axis.
  Assumption (1 mrad); inside the IMU the LN-200's own axis alignment is much better (datasheet class, tens of
  micro-radians), so the mounting dominates.
* ``gyro_scale_factor_ppm`` / ``accel_scale_factor_ppm``: per-axis scale-factor errors, Litton LN-200 datasheet
  ("scale factor stability" 100 ppm for the gyros, 300 ppm for the accelerometers, 1 sigma).
* ``sinkage_rolling_radius`` (off in both profiles, opt-in): the wheel's effective rolling radius shrinks with its
  sinkage, ``r - z`` in the slip kinematics of the default (Bekker) soil law (:mod:`rover_sim.sim.terramechanics`).
  It changes the truth (a sunk wheel advances less per turn) while the onboard odometry keeps the nominal radius.
  Not small here: the sim's sand sinks the wheels about 6.4 mm (z/r = 5 %); on flat sand (3 m, seed 5, ideal
  sensors) turning it on raised the mean slip from 3.8 to 8.7 % and the DR error from 3.9 to 9.5 % of distance,
  and it would shift every slip anchor ``bench slip`` was calibrated on (made with the undeformed radius, as
  Wong's rigid-wheel slip is defined). So it stays off until the soil law is recalibrated with it. The
  ``wong_reece`` law (the scenarios' default) does not model it either.
* ``heading_error_deg``: the heading of the operator-given start pose (from sun finding) is off by a draw of this
  1 sigma; the truth is not changed. MER sun finding gave heading to about 1.5 deg (Ali et al. 2005, "Attitude and
  position estimation on the Mars Exploration Rovers", as quoted by Wang et al. 2018); we read that as a 3-sigma
  bound: 1 sigma = 0.5 deg.

``profile = "ideal"`` makes every term zero (today's behaviour, bit for bit: no random numbers are drawn).
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

FLIGHT_DEFAULTS: dict[str, float] = {
    "wheel_radius_error_pct": 1.0,
    "steer_offset_deg": 0.5,
    "imu_misalignment_mrad": 1.0,
    "gyro_scale_factor_ppm": 100.0,
    "accel_scale_factor_ppm": 300.0,
    "heading_error_deg": 0.5,
}
DRAWN = tuple(FLIGHT_DEFAULTS)  # the seeded terms (rover_sim.sim.sensors.OdometryErrors.draw's arguments)


class OdometryErrorSpec(BaseModel):
    """``[sensors.odometry]``: 1-sigma sizes of the odometry and attitude errors (0 = none)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    wheel_radius_error_pct: float = Field(0.0, ge=0.0, le=20.0, description="1 sigma per wheel, % of radius.")
    steer_offset_deg: float = Field(0.0, ge=0.0, le=10.0, description="1 sigma per steered wheel, deg.")
    imu_misalignment_mrad: float = Field(0.0, ge=0.0, le=50.0, description="1 sigma per axis, mrad.")
    gyro_scale_factor_ppm: float = Field(0.0, ge=0.0, le=1e5, description="1 sigma per axis, ppm.")
    accel_scale_factor_ppm: float = Field(0.0, ge=0.0, le=1e5, description="1 sigma per axis, ppm.")
    heading_error_deg: float = Field(0.0, ge=0.0, le=30.0, description="1 sigma of the start heading, deg.")
    sinkage_rolling_radius: bool = Field(False, description="Rolling radius r - z, Bekker law only; opt-in.")

    @classmethod
    def profile_defaults(cls, profile: str) -> dict[str, Any]:
        """The flight sizes (module docstring) or all zeros; the sinkage rolling radius is opt-in in both."""
        flight = profile == "flight"
        return {**(FLIGHT_DEFAULTS if flight else dict.fromkeys(DRAWN, 0.0)), "sinkage_rolling_radius": False}

    def drawn_sizes(self) -> dict[str, float]:
        """The 1-sigma sizes of the seeded terms, as keyword arguments of ``OdometryErrors.draw``."""
        return {k: getattr(self, k) for k in DRAWN}

    @property
    def is_ideal(self) -> bool:
        return not self.sinkage_rolling_radius and all(getattr(self, k) == 0.0 for k in DRAWN)
