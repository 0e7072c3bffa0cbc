"""Scenario files: one TOML schema, validated on load with errors naming the file, the field and the allowed range.

A scenario is the terrain recipe, the sun, the rover's start pose, the command sequence as MER was commanded
(blind drives, arcs, turns, VO-corrected goto, autonav to a waypoint, mast pointing, sleep to the next sol),
keep-out zones and a slip limit, the navigation configuration, and the pass criterion. ``--set dotted.key=value``
overrides any field. The tables are defined beside this module (``world_spec``, ``nav_spec``, ``commands``,
``criteria``, ``sensors_spec``); :mod:`rover_sim.scenario.loading` reads files and applies overrides.
"""

from __future__ import annotations

import json
from typing import Any

from pydantic import ConfigDict, Field, model_validator

from rover_sim.orbital.spec import OrbitalSpec
from rover_sim.scenario.base import Spec
from rover_sim.scenario.commands import Command, KeepOut, SleepCmd, SolSpec
from rover_sim.scenario.criteria import PassSpec
from rover_sim.scenario.nav_spec import NavSpec
from rover_sim.scenario.sensors_spec import SensorsSpec
from rover_sim.scenario.world_spec import (
    MIN_SUN_ELEVATION_DEG,
    AppearanceSpec,
    FaultSpec,
    PhysicsSpec,
    StartSpec,
    SunSpec,
)
from rover_sim.sim.ephemeris import sun_azimuth_elevation_deg
from terrains import TerrainRecipe


class Scenario(Spec):
    name: str = Field(min_length=1, max_length=64, pattern=r"^[a-z0-9_]+$")
    description: str = ""
    seed: int = Field(0, ge=0, le=2**31 - 1)
    terrain: TerrainRecipe = Field(default_factory=TerrainRecipe)
    sun: SunSpec = Field(default_factory=SunSpec)
    appearance: AppearanceSpec = Field(default_factory=AppearanceSpec)
    start: StartSpec = Field(default_factory=StartSpec)
    nav: NavSpec = Field(default_factory=NavSpec)
    commands: list[Command] = Field(min_length=1, max_length=500)
    keep_out: list[KeepOut] = Field(default_factory=list)
    faults: FaultSpec = Field(default_factory=FaultSpec)
    passing: PassSpec = Field(default_factory=PassSpec, alias="pass")
    physics: PhysicsSpec = Field(default_factory=PhysicsSpec)
    sensors: SensorsSpec = Field(default_factory=SensorsSpec)
    fast: bool = Field(False, description="Part of the fast CI suite.")
    sol: SolSpec | None = Field(None, description="Drive-time and distance budgets of a sol's drive.")
    orbital: OrbitalSpec = Field(default_factory=OrbitalSpec, description="Orbital products' error model.")

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, populate_by_name=True)

    @model_validator(mode="after")
    def _start_on_patch(self) -> Scenario:
        if self.terrain.streamed is not None:  # the first window is built around the start: any start is on the site
            return self
        nrow, ncol = self.terrain.grid_shape
        half_x = (ncol - 1) * self.terrain.cell_size_m / 2 - 1.0
        half_y = (nrow - 1) * self.terrain.cell_size_m / 2 - 1.0
        if abs(self.start.x_m) > half_x or abs(self.start.y_m) > half_y:
            raise ValueError(
                f"start ({self.start.x_m}, {self.start.y_m}) must be at least 1 m inside the terrain "
                f"(|x| <= {half_x:.1f}, |y| <= {half_y:.1f})"
            )
        return self

    @model_validator(mode="after")
    def _drift_needs_wong_reece(self) -> Scenario:
        if self.terrain.drift_ripples and self.physics.soil_model != "wong_reece":
            raise ValueError(
                "terrain.drift_ripples need physics.soil_model = 'wong_reece' (the 'bekker' law has no drift "
                f"soil); got {self.physics.soil_model!r}"
            )
        if self.physics.deformable and self.terrain.streamed is not None:
            raise ValueError(
                "physics.deformable = true is not supported on a streamed terrain (terrain.streamed) yet: ruts would "
                "have to follow the moving window; turn one of them off"
            )
        p = self.passing
        if (p.min_final_sinkage_m is not None or p.max_final_sinkage_m is not None) and not self.physics.deformable:
            raise ValueError(
                "pass.min_final_sinkage_m / max_final_sinkage_m measure the wheels' depth in the deformed ground: "
                "they need physics.deformable = true (and soil_model = 'wong_reece')"
            )
        return self

    @model_validator(mode="after")
    def _sleep_needs_a_sol(self) -> Scenario:
        for i, cmd in enumerate(self.commands):
            if not isinstance(cmd, SleepCmd):
                continue
            if self.sol is None:
                raise ValueError(f"commands.{i}: a 'sleep' command needs a [sol] table (the mission clock and budgets)")
            wake_h = self.wake_local_solar_time_h(cmd)
            if self.sun.local_solar_time_h is not None:  # a moving sun: the rover must wake in daylight
                el = sun_azimuth_elevation_deg(self.sun.latitude_deg, self.sun.solar_longitude_deg, wake_h)[1]
                if el < MIN_SUN_ELEVATION_DEG:
                    raise ValueError(
                        f"commands.{i}.wake_local_solar_time_h = {wake_h}: the sun is {el:.1f} deg high; choose a "
                        f"time with it >= {MIN_SUN_ELEVATION_DEG} deg"
                    )
        return self

    def wake_local_solar_time_h(self, cmd: SleepCmd) -> float:
        """When ``cmd`` wakes the rover: its own time, else the time of day the drive started (the mission clock's
        start: ``sun.local_solar_time_h`` if set, else ``[sol] start_local_solar_time_h``)."""
        if cmd.wake_local_solar_time_h is not None:
            return cmd.wake_local_solar_time_h
        if self.sun.local_solar_time_h is not None:
            return self.sun.local_solar_time_h
        assert self.sol is not None
        return self.sol.start_local_solar_time_h

    def resolved_dict(self) -> dict[str, Any]:
        d = json.loads(self.model_dump_json(by_alias=True))
        if d["terrain"].get("streamed", 0) is None:  # opt-in streaming: whole-site scenario.json files unchanged
            del d["terrain"]["streamed"]
        if d["terrain"].get("drift_ripples", 0) == []:  # opt-in drift (purgatory_ripple): other files unchanged
            del d["terrain"]["drift_ripples"]
        if d.get("sol", 0) is None:
            del d["sol"]
        return d
