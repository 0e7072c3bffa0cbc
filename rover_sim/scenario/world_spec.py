"""The world a scenario sets up: the sun (fixed, or moving along the ephemeris), the ground's appearance, the rover's
start pose, hardware faults and the physics options."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from rover_sim.scenario.base import Spec
from rover_sim.sim.ephemeris import sun_azimuth_elevation_deg

MIN_SUN_ELEVATION_DEG = 2.0  # lowest sun the renderer is asked for (shadow maps degrade at grazing light)


class SunSpec(Spec):
    """The sun: fixed (``azimuth_deg``, ``elevation_deg``) or, with ``local_solar_time_h``, moving with the time of
    day along the ephemeris (:mod:`rover_sim.sim.ephemeris`) while the mission clock runs."""

    azimuth_deg: float = Field(135.0, ge=-360.0, le=360.0, description="From +x (east) toward +y (north).")
    elevation_deg: float = Field(45.0, ge=2.0, le=90.0, description="Above the horizon.")
    shadows: bool = True
    latitude_deg: float = Field(0.0, ge=-90.0, le=90.0, description="Site latitude (ephemeris only).")
    solar_longitude_deg: float = Field(0.0, ge=0.0, lt=360.0, description="Season Ls (ephemeris only).")
    local_solar_time_h: float | None = Field(
        None, ge=0.0, lt=24.0, description="LTST at the start of the drive; set: the sun follows the ephemeris."
    )

    @model_validator(mode="after")
    def _sun_above_horizon(self) -> SunSpec:
        if self.local_solar_time_h is not None:
            el = sun_azimuth_elevation_deg(self.latitude_deg, self.solar_longitude_deg, self.local_solar_time_h)[1]
            if el < MIN_SUN_ELEVATION_DEG:
                raise ValueError(
                    f"sun.local_solar_time_h = {self.local_solar_time_h}: the sun is {el:.1f} deg high at latitude "
                    f"{self.latitude_deg}, Ls {self.solar_longitude_deg}; choose a time with it >= "
                    f"{MIN_SUN_ELEVATION_DEG} deg"
                )
        return self

    def azimuth_elevation_at(self, local_solar_time_h: float | None) -> tuple[float, float]:
        """(azimuth, elevation) in degrees at ``local_solar_time_h`` (fixed values without an ephemeris time)."""
        if local_solar_time_h is None:
            return self.azimuth_deg, self.elevation_deg
        az, el = sun_azimuth_elevation_deg(self.latitude_deg, self.solar_longitude_deg, local_solar_time_h)
        return az, max(el, MIN_SUN_ELEVATION_DEG)  # a drive running into dusk keeps a grazing sun


class TexturePatch(Spec):
    """A disc of coarser soil (granules, drift edges, old tracks) inside ``fine_soil``: where texture exists."""

    x_m: float = Field(ge=-1.0e4, le=1.0e4)
    y_m: float = Field(ge=-1.0e4, le=1.0e4)
    radius_m: float = Field(gt=0.0, le=100.0)
    detail: float = Field(1.0, gt=0.0, le=2.0, description="Sand detail relative to ordinary soil (1 = ordinary).")


class AppearanceSpec(Spec):
    """Ground albedo: ``fine_soil`` makes sand nearly featureless (Meridiani plains) to starve stereo and VO;
    ``texture_patches`` state where, inside it, the soil is coarse enough to track (the scenario says where
    texture exists)."""

    fine_soil: bool = False
    contrast: float = Field(1.0, gt=0.0, le=3.0, description="Albedo contrast multiplier.")
    texture_px_per_m: float = Field(100.0, ge=10.0, le=200.0, description="Texels per metre (capped by GL size).")
    texture_patches: list[TexturePatch] = Field(default_factory=list, max_length=200)
    regolith: Literal["classic", "multiscale"] = Field(
        "multiscale",
        description="Soil texture: 'classic' FFT speckle or 'multiscale' (fine soil, pebbles, clasts, "
        "relief shaded by the sun; terrains.regolith).",
    )

    def patch_tuples(self) -> tuple[tuple[float, float, float, float], ...]:
        return tuple((p.x_m, p.y_m, p.radius_m, p.detail) for p in self.texture_patches)


class StartSpec(Spec):
    x_m: float = Field(0.0, ge=-1.0e4, le=1.0e4)
    y_m: float = Field(0.0, ge=-1.0e4, le=1.0e4)
    yaw_deg: float = Field(0.0, ge=-360.0, le=360.0, description="Heading from +x toward +y.")


class FaultSpec(Spec):
    """Hardware faults: a locked wheel is held by its drive and dragged (Spirit's right front, Sol 170 on)."""

    locked_wheels: list[Literal["lf", "lm", "lr", "rf", "rm", "rr"]] = Field(default_factory=list, max_length=6)


class PhysicsSpec(Spec):
    timestep_s: float = Field(
        0.005,
        ge=0.0005,
        le=0.01,
        description="Physics step, s. 0.005 is the step the soil law was calibrated at (every catalogue scenario); a "
        "coarser step trades slip accuracy for speed (docs/physics/streamed-terrain.md).",
    )
    soil_model: Literal["bekker", "wong_reece"] = Field(
        "wong_reece",
        description="Wheel-soil law: 'wong_reece' (default: stress distribution, two-scale shear, the wheels' own "
        "cylinder contact) or the earlier 'bekker' patch law (docs/physics/index.md).",
    )
    deformable: bool = Field(
        False, description="Ruts, berms and multipass in the heightfield (opt-in); needs 'wong_reece'."
    )
    perturb_size: float = Field(0.0, ge=0.0, le=0.01, description="A seeded 'butterfly' added to the settled "
                                "rover: metres and radians, seeded directions (another CPU or build).")  # fmt: skip
    perturb_seed: int = Field(0, ge=0, le=2**31 - 1, description="Seed of the perturbation's directions.")

    @model_validator(mode="after")
    def _deformable_needs_wong_reece(self) -> PhysicsSpec:
        if self.deformable and self.soil_model != "wong_reece":
            raise ValueError(
                "physics.deformable = true needs physics.soil_model = 'wong_reece' "
                f"(allowed soil_model values: 'bekker', 'wong_reece'; got {self.soil_model!r})"
            )
        return self
