"""``[sensors]``: how far the simulated sensors are from ideal.

``profile = "flight"`` gives every error term the size flight hardware had (docs/physics/error-budget.md);
``profile = "ideal"`` zeroes them (perfect calibration, no lens distortion, exact odometry geometry). Every term
stays configurable on its own and every random draw is seeded from the scenario seed.

Each error family is a sub-table with its own model (``[sensors.<name>]``), registered in :data:`SUBTABLES`. A
sub-model class provides ``profile_defaults(profile) -> dict``: the values the profile implies. Values the
scenario (or ``--set sensors.<name>.<field>=...``) gives explicitly override them.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from rover_sim.render.imaging import ImagingSpec
from rover_sim.scenario.lens_spec import LensErrorSpec
from rover_sim.scenario.odometry_spec import OdometryErrorSpec

Profile = Literal["flight", "ideal"]
DEFAULT_PROFILE: Profile = "flight"

#: sub-table name -> model class (with ``profile_defaults(profile) -> dict``); filled as error families land
SUBTABLES: dict[str, type[BaseModel]] = {"lens": LensErrorSpec, "imaging": ImagingSpec, "odometry": OdometryErrorSpec}


class SensorsSpec(BaseModel):
    """``[sensors]``: the profile and, per error family, its sub-table."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, validate_default=True)

    profile: Profile = Field(DEFAULT_PROFILE, description="'flight' (errors as flown) or 'ideal' (none).")
    lens: LensErrorSpec = Field(default_factory=LensErrorSpec, description="lens models, calibration, mast encoders")
    imaging: ImagingSpec = Field(default_factory=ImagingSpec)
    odometry: OdometryErrorSpec = Field(default_factory=OdometryErrorSpec)

    @model_validator(mode="before")
    @classmethod
    def _profile_defaults(cls, data: Any) -> Any:
        """Fill each sub-table with its profile's defaults under whatever the scenario set explicitly."""
        if not isinstance(data, dict):
            return data
        profile = data.get("profile", DEFAULT_PROFILE)
        if profile not in ("flight", "ideal"):
            return data  # the field validator names the allowed values
        out = dict(data)
        for name, model in SUBTABLES.items():
            given = out.get(name)
            if given is None or isinstance(given, dict):
                out[name] = {**model.profile_defaults(profile), **(given or {})}  # type: ignore[attr-defined]
        return out
