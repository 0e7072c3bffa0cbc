"""Scenario files: one TOML schema, validated on load with errors naming the file, the field and the allowed range.

A scenario is the terrain recipe, the sun, the rover's start pose, the command sequence as MER was commanded
(blind drives, arcs, turns, VO-corrected goto, autonav to a waypoint, mast pointing, sleep to the next sol),
keep-out zones and a slip limit, the navigation configuration, and the pass criterion. ``--set dotted.key=value``
overrides any field.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from nav.gestalt import GestaltParams
from nav.stereo import StereoParams
from nav.vo import SanityConstraints, VoParams
from rover_sim.errors import ConfigError, UnknownScenario
from rover_sim.mission.sensors_spec import SensorsSpec
from rover_sim.orbital.spec import OrbitalSpec
from rover_sim.resources import scenarios_dir
from rover_sim.sim.ephemeris import sun_azimuth_elevation_deg
from terrains import TerrainRecipe

SCENARIOS_DIR = scenarios_dir()
MIN_SUN_ELEVATION_DEG = 2.0  # lowest sun the renderer is asked for (shadow maps degrade at grazing light)


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, validate_default=True)


class SunSpec(_Spec):
    """The sun: fixed (``azimuth_deg``, ``elevation_deg``) or, with ``local_solar_time_h``, moving with the time of
    day along the ephemeris (:mod:`rover_sim.sim.ephemeris`) while the mission clock runs (issue #16 item 4)."""

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


class TexturePatch(_Spec):
    """A disc of coarser soil (granules, drift edges, old tracks) inside ``fine_soil``: where texture exists."""

    x_m: float = Field(ge=-1.0e4, le=1.0e4)
    y_m: float = Field(ge=-1.0e4, le=1.0e4)
    radius_m: float = Field(gt=0.0, le=100.0)
    detail: float = Field(1.0, gt=0.0, le=2.0, description="Sand detail relative to ordinary soil (1 = ordinary).")


class AppearanceSpec(_Spec):
    """Ground albedo: ``fine_soil`` makes sand nearly featureless (Meridiani plains) to starve stereo and VO;
    ``texture_patches`` state where, inside it, the soil is coarse enough to track (the scenario says where
    texture exists, issue #17)."""

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


class StartSpec(_Spec):
    x_m: float = Field(0.0, ge=-1.0e4, le=1.0e4)
    y_m: float = Field(0.0, ge=-1.0e4, le=1.0e4)
    yaw_deg: float = Field(0.0, ge=-360.0, le=360.0, description="Heading from +x toward +y.")


BUILTIN = "builtin"
IMPL_DESCRIPTION = (
    '"builtin", an import path "package.module:Class", or the name of an entry point in the group "rover_sim.plugins"'
)


def _split_params(data: Any, own: tuple[str, ...], shorthand: str | None) -> Any:
    """Let a ``[nav.<part>]`` table hold its algorithm parameters flat (``--set nav.vo.window_px=9``).

    Keys that are not the part's own settings go into ``params``; a bare bool or string is shorthand for
    ``enabled`` or ``impl`` (``[nav] vo = false``, ``vo = "mypkg.vo:MyVO"``).
    """
    if isinstance(data, bool) and shorthand == "enabled":
        return {"enabled": data}
    if isinstance(data, str):
        return {"impl": data}
    if not isinstance(data, dict):
        return data
    out = {k: v for k, v in data.items() if k in own or k == "params"}
    flat = {k: v for k, v in data.items() if k not in out}
    if flat:
        out["params"] = {**(out.get("params") or {}), **flat}
    return out


class VoSpec(_Spec):
    """``[nav.vo]``: visual odometry on/off, which implementation, its parameters and MER's sanity constraints."""

    enabled: bool = Field(True, description="Visual odometry on (MER used it on slopes and in sand).")
    impl: str = Field(BUILTIN, min_length=1, description=IMPL_DESCRIPTION)
    sanity: SanityConstraints = Field(default_factory=SanityConstraints)
    params: VoParams = Field(default_factory=VoParams)
    shadow_mask: bool = Field(True, description="Bar features in and near the rover's predicted shadow (issue #17).")
    seek_texture: bool = Field(True, description="Repoint the mast at texture when the planned view is poor.")
    update: Literal["position", "full_pose"] = Field(
        "position",
        description="What an accepted VO step corrects: 'position' (MER: the IMU keeps attitude) or "
        "'full_pose' (attitude too).",
    )

    @model_validator(mode="before")
    @classmethod
    def _flat(cls, data: Any) -> Any:
        own = ("enabled", "impl", "sanity", "shadow_mask", "seek_texture", "update")
        return _split_params(data, own, "enabled")


class StereoSpec(_Spec):
    """``[nav.stereo]``: the dense stereo used for autonav ranging and the recording's depth."""

    impl: str = Field(BUILTIN, min_length=1, description=IMPL_DESCRIPTION)
    params: StereoParams = Field(default_factory=StereoParams)

    @model_validator(mode="before")
    @classmethod
    def _flat(cls, data: Any) -> Any:
        return _split_params(data, ("impl",), None)


class PlannerSpec(_Spec):
    """``[nav.planner]``: the autonav planner (GESTALT by default) and its parameters."""

    impl: str = Field(BUILTIN, min_length=1, description=IMPL_DESCRIPTION)
    params: GestaltParams = Field(default_factory=GestaltParams)

    @model_validator(mode="before")
    @classmethod
    def _flat(cls, data: Any) -> Any:
        return _split_params(data, ("impl",), None)


class NavSpec(_Spec):
    vo: VoSpec = Field(default_factory=VoSpec)
    stereo: StereoSpec = Field(default_factory=StereoSpec)
    planner: PlannerSpec = Field(default_factory=PlannerSpec)
    vo_step_m: float = Field(0.35, gt=0.05, le=0.75, description="Drive between VO images (MER: <= 75 cm).")
    camera: Literal["navcam", "hazcam_front"] = "navcam"
    resolution_px: int = Field(256, ge=64, le=1024, description="Navigation image size (MER binned to 256).")
    mast_pan_deg: float = Field(0.0, ge=-180.0, le=180.0)
    mast_tilt_deg: float = Field(
        -40.0, ge=-70.0, le=85.0, description="Navcam elevation: negative looks down (joint range -74..+86 deg)."
    )
    speed_m_s: float = Field(0.0375, gt=0.0, le=0.05, description="Wheel speed (MER peak 5 cm/s).")
    slip_limit: float | None = Field(
        None, gt=0.0, le=2.0, description="Halt when a VO step measures more slip than this (MER: 0.4)."
    )
    image_noise: bool = True
    epipolar_check: bool = Field(
        True,
        description="Flight profile: fit each stereo pair's relative pitch and roll from its first images' row "
        "disparities and rectify with the corrected calibration (nav/epipolar.py).",
    )


class FaultSpec(_Spec):
    """Hardware faults: a locked wheel is held by its drive and dragged (Spirit's right front, Sol 170 on)."""

    locked_wheels: list[Literal["lf", "lm", "lr", "rf", "rm", "rr"]] = Field(default_factory=list, max_length=6)


class DriveCmd(_Spec):
    """Blind straight drive: ends when the wheels have turned ``distance_m``."""

    type: Literal["drive"]
    distance_m: float = Field(ge=-50.0, le=50.0)


class ArcCmd(_Spec):
    type: Literal["arc"]
    radius_m: float = Field(ge=-1000.0, le=1000.0, description="> 0 turns left; |radius| >= 0.3 m.")
    distance_m: float = Field(ge=-50.0, le=50.0)

    @model_validator(mode="after")
    def _radius(self) -> ArcCmd:
        if abs(self.radius_m) < 0.3:
            raise ValueError("|radius_m| must be >= 0.3 m (use a turn command for a point turn)")
        return self


class TurnCmd(_Spec):
    type: Literal["turn"]
    angle_deg: float = Field(ge=-360.0, le=360.0)


class GotoCmd(_Spec):
    """Drive to a point using the onboard (VO-corrected if VO is on) pose, in steps of ``nav.vo_step_m``."""

    type: Literal["goto"]
    x_m: float = Field(ge=-1.0e4, le=1.0e4)
    y_m: float = Field(ge=-1.0e4, le=1.0e4)
    tolerance_m: float = Field(0.2, gt=0.0, le=10.0)
    max_distance_m: float = Field(60.0, gt=0.0, le=500.0, description="Commanded-travel budget before giving up.")


class AutonavCmd(_Spec):
    """GESTALT autonomous navigation to a waypoint."""

    type: Literal["autonav"]
    x_m: float = Field(ge=-1.0e4, le=1.0e4)
    y_m: float = Field(ge=-1.0e4, le=1.0e4)
    tolerance_m: float = Field(1.0, gt=0.0, le=10.0)
    step_m: float = Field(0.5, ge=0.35, le=1.0, description="Drive per GESTALT cycle (MER: 35 cm to 1 m).")
    max_cycles: int = Field(120, ge=1, le=2000)


class MastCmd(_Spec):
    type: Literal["mast"]
    pan_deg: float = Field(ge=-180.0, le=180.0)
    tilt_deg: float = Field(ge=-70.0, le=85.0, description="Elevation: negative looks down.")


class SleepCmd(_Spec):
    """End of sol (issue #18): the rover parks, wheels held, and sleeps until the next sol's wake-up time on the
    mission clock; the next sol's budgets start then. Needs a ``[sol]`` table."""

    type: Literal["sleep"]
    wake_local_solar_time_h: float | None = Field(
        None, ge=0.0, lt=24.0,
        description="Local solar time the rover wakes at, next sol (default: the time of day the drive started).",
    )  # fmt: skip


Command = Annotated[
    DriveCmd | ArcCmd | TurnCmd | GotoCmd | AutonavCmd | MastCmd | SleepCmd, Field(discriminator="type")
]


class KeepOut(_Spec):
    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$")
    x_m: float = Field(ge=-1.0e4, le=1.0e4)
    y_m: float = Field(ge=-1.0e4, le=1.0e4)
    radius_m: float = Field(gt=0.0, le=100.0, description="Halt when the onboard pose comes this close.")


# metrics a distribution criterion may bound (read from metrics.json: rover_sim.bench.seeded.METRICS)
DISTRIBUTION_METRICS = ("vo_error_pct", "dr_error_pct", "vo_convergence_pct", "max_slip_pct", "goal_distance_m",
                        "false_positives", "distance_m")  # fmt: skip


class DistributionSpec(_Spec):
    """``[pass.distribution]``: criteria over seeds (``bench suite --seeds``): at least ``min_pass_rate`` of the
    seeds meet the per-run criteria (default: ``acceptance.DEFAULT_MIN_PASS_RATE``) and every bound holds."""

    min_pass_rate: float | None = Field(None, ge=0.0, le=1.0, description="Fraction of seeds that must pass.")
    max_median: dict[str, float] = Field(default_factory=dict, description="metric -> upper bound of its median")
    min_median: dict[str, float] = Field(default_factory=dict, description="metric -> lower bound of its median")
    max_p90: dict[str, float] = Field(default_factory=dict, description="metric -> upper bound of its 90th pct")

    @model_validator(mode="after")
    def _known_metrics(self) -> DistributionSpec:
        for table in ("max_median", "min_median", "max_p90"):
            for key in getattr(self, table):
                if key not in DISTRIBUTION_METRICS:
                    raise ValueError(f"{table}: unknown metric {key!r} (allowed: {', '.join(DISTRIBUTION_METRICS)})")
        return self


class PassSpec(_Spec):
    """The scenario's pass criterion; every set bound must hold."""

    max_vo_error_pct: float | None = Field(None, gt=0.0, le=100.0)
    min_dr_error_pct: float | None = Field(None, ge=0.0, le=1000.0)
    max_dr_error_pct: float | None = Field(None, gt=0.0, le=1000.0)
    min_vo_convergence_pct: float | None = Field(None, ge=0.0, le=100.0)
    justified_refusals: bool = Field(
        False,
        description="min_vo_convergence_pct counts only steps where some pointing had texture: a refusal logged as "
        "'no pointing had texture' is justified (featureless ground, issue #17).",
    )
    min_max_slip_pct: float | None = Field(None, ge=0.0, le=500.0)
    max_max_slip_pct: float | None = Field(None, ge=0.0, le=500.0)
    max_false_positives: int | None = Field(None, ge=0, le=1000)
    expect_halt: Literal["keep_out", "slip_limit", "vo_failures"] | None = None
    expect_dead_reckoning_clear: bool = Field(
        False, description="At a keep-out halt, dead reckoning alone still believes the rover outside the zone."
    )
    goal_within_m: float | None = Field(None, gt=0.0, le=100.0, description="Truth within this of the last goal.")
    max_body_collisions: int | None = Field(
        None, ge=0, le=1000, description="Ticks with the body touching anything, or any part touching a rock >= 25 cm."
    )
    # embedding (issue #13, purgatory_ripple): the wheels' state at the end of the run, from truth
    min_final_sinkage_m: float | None = Field(
        None, ge=0.0, le=0.5,
        description="Mean depth of the six wheels' bottoms below the undisturbed ground at the end (deformable).",
    )  # fmt: skip
    max_final_sinkage_m: float | None = Field(None, ge=0.0, le=0.5, description="Upper bound of the same.")
    min_final_slip_pct: float | None = Field(
        None, ge=0.0, le=500.0, description="Slip over the last metre of commanded wheel travel (truth)."
    )

    distribution: DistributionSpec = Field(default_factory=DistributionSpec)

    def judges_wheels(self) -> bool:
        """True when a criterion needs the end-of-run wheel metrics (``metrics.extra["wheels"]``)."""
        bounds = (self.min_final_sinkage_m, self.max_final_sinkage_m, self.min_final_slip_pct)
        return any(b is not None for b in bounds)


class SolSpec(_Spec):
    """``[sol]``: the day's drive as MER flew it (issue #18): the commands run until the drive-time budget (mission
    clock: driving + imaging + computing, ``rover_sim/mission/clock.py``) or the odometry distance budget is spent.
    A drive of several sols separates them with ``sleep`` commands: the budgets apply to each sol, and a sol whose
    budget is spent skips the rest of its commands up to the next ``sleep``. Long drives keep fewer poses
    (``pose_stride``) so memory and the recording grow slowly with distance."""

    max_time_s: float = Field(gt=0.0, le=86400.0, description="Drive-time budget of each sol on the mission clock, s.")
    max_distance_m: float | None = Field(None, gt=0.0, le=5000.0, description="Odometry budget of each sol, m.")
    start_local_solar_time_h: float = Field(11.0, ge=0.0, lt=24.0, description="Local solar time at the start.")
    pose_stride: int = Field(1, ge=1, le=64, description="Ticks (8 Hz) between kept poses and logged poses.")
    vo_min_slope_deg: float | None = Field(
        None, ge=0.0, le=45.0, description="Blind drives image VO only where the onboard tilt exceeds this (MER)."
    )
    benchmark_only: bool = Field(False, description="A bench traverse case, not part of the scenario catalogue.")


class PhysicsSpec(_Spec):
    timestep_s: float = Field(
        0.005, ge=0.0005, le=0.01,
        description="Physics step, s. 0.005 is the step the soil law was calibrated at (every catalogue scenario); a "
        "coarser step trades slip accuracy for speed (README: Speed of long drives).",
    )
    soil_model: Literal["bekker", "wong_reece"] = Field(
        "wong_reece",
        description="Wheel-soil law: 'wong_reece' (default: stress distribution, two-scale shear, the wheels' own "
        "cylinder contact) or the earlier 'bekker' patch law (README: The wheel-soil law).",
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


class Scenario(_Spec):
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
    sol: SolSpec | None = Field(None, description="Drive-time and distance budgets of a sol's drive (issue #18).")
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


def _list_index(node: list, key: str, dotted: str, where: str) -> int:
    """``key`` as an index into ``node`` (the list at ``where``), or a ConfigError naming the list's length."""
    try:
        i = int(key)
    except ValueError:
        problem = f"'{where}' is a list: '{key}' is not an index (0..{len(node) - 1})"
        raise ConfigError("--set", dotted, problem) from None
    if not 0 <= i < len(node):
        n = len(node)
        raise ConfigError(
            "--set", dotted, f"index {i} out of range: '{where}' has {n} item{'s' if n != 1 else ''} (0..{n - 1})"
        )
    return i


def _set_dotted(tree: dict, dotted: str, value: Any) -> None:
    keys = dotted.split(".")
    if not all(keys):
        raise ConfigError("--set", dotted, "empty key (expected dotted.key=value)")
    node: Any = tree
    for depth, k in enumerate(keys[:-1]):
        where = ".".join(keys[:depth]) or "(top level)"
        if isinstance(node, list):
            node = node[_list_index(node, k, dotted, where)]
        else:
            node = node.setdefault(k, {})
        if not isinstance(node, dict | list):
            raise ConfigError("--set", dotted, f"'{k}' is a value, not a table")
    last = keys[-1]
    if isinstance(node, list):
        node[_list_index(node, last, dotted, ".".join(keys[:-1]))] = value
    else:
        node[last] = value


def parse_override(text: str) -> tuple[str, Any]:
    """``a.b=1.5`` -> ("a.b", 1.5); the value is parsed as TOML (numbers, booleans, strings, arrays)."""
    if "=" not in text:
        raise ConfigError("--set", text, "expected dotted.key=value")
    key, raw = text.split("=", 1)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw  # a bare string
    return key.strip(), value


def _describe(err: ValidationError) -> tuple[str, str]:
    first = err.errors()[0]
    loc = ".".join(str(p) for p in first["loc"]) or "(top level)"
    msg = first["msg"]
    ctx = first.get("ctx") or {}
    bounds = ", ".join(f"{k} {v}" for k, v in ctx.items() if k in ("ge", "gt", "le", "lt", "expected"))
    if bounds:
        msg = f"{msg} (allowed: {bounds})"
    if first.get("input") is not None and not isinstance(first.get("input"), dict | list):
        msg = f"{msg}; got {first['input']!r}"
    more = len(err.errors()) - 1
    if more:
        msg += f" (+{more} more problem{'s' if more > 1 else ''})"
    return loc, msg


def _normalise_nav(tree: dict) -> None:
    """``[nav] vo = false`` / ``vo = "pkg.mod:Class"`` shorthands become tables, so ``--set nav.vo.x=...`` works."""
    nav = tree.get("nav")
    if not isinstance(nav, dict):
        return
    for part in ("vo", "stereo", "planner"):
        value = nav.get(part)
        if isinstance(value, bool) and part == "vo":
            nav[part] = {"enabled": value}
        elif isinstance(value, str):
            nav[part] = {"impl": value}


def plugin_overrides(vo: str | None = None, stereo: str | None = None, planner: str | None = None) -> list[str]:
    """``--set`` overrides that select the given implementations (``--vo`` also turns VO on)."""
    out = []
    if vo:
        out += ["nav.vo.enabled=true", f'nav.vo.impl="{vo}"']
    if stereo:
        out.append(f'nav.stereo.impl="{stereo}"')
    if planner:
        out.append(f'nav.planner.impl="{planner}"')
    return out


def _blamed_override(loc: str, overrides: list[str], flags: list[str]) -> str | None:
    """The flag (``--set key=value``, ``--seed N``) whose key the invalid field ``loc`` belongs to, if any: the
    key's parts appear in order in ``loc`` (a command's type tag may sit between them), or ``loc`` is the start of
    the key (an unknown key is reported at its first unknown part)."""
    parts = loc.split(".")
    for text, flag in reversed(list(zip(overrides, flags, strict=True))):
        key = parse_override(text)[0].split(".")
        it = iter(parts)
        if all(k in it for k in key) or key[: len(parts)] == parts:
            return flag
    return None


def scenario_from_dict(
    data: dict, source: str = "<dict>", overrides: list[str] | None = None, flags: list[str] | None = None
) -> Scenario:
    """Validate ``data`` with ``overrides`` (``dotted.key=value``) applied. A field made invalid by an override is
    reported against the flag that set it (``flags[i]`` for ``overrides[i]``; default ``--set <override>``),
    not against ``source``."""
    overrides = list(overrides or [])
    flags = list(flags) if flags is not None else [f"--set {o}" for o in overrides]
    tree = json.loads(json.dumps(data))  # deep copy of plain data
    _normalise_nav(tree)
    for text in overrides:
        key, value = parse_override(text)
        _set_dotted(tree, key, value)
    try:
        return Scenario.model_validate(tree)
    except ValidationError as err:
        loc, msg = _describe(err)
        raise ConfigError(_blamed_override(loc, overrides, flags) or source, loc, msg) from None


def load_scenario(
    name_or_path: str | Path,
    overrides: list[str] | None = None,
    seed: int | None = None,
    flags: list[str] | None = None,
) -> Scenario:
    """Load ``scenarios/<name>.toml`` or a path; apply ``--set`` overrides and ``--seed``. An invalid value is
    reported against its flag: ``flags[i]`` for ``overrides[i]`` (default ``--set <override>``), ``--seed N``."""
    path = Path(name_or_path)
    if not path.suffix:
        path = SCENARIOS_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        raise UnknownScenario(str(name_or_path), catalogue(), is_name=not Path(name_or_path).suffix)
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigError(str(path), "(syntax)", f"not valid TOML: {err}") from None
    extra = list(overrides or [])
    flags = list(flags) if flags is not None else [f"--set {o}" for o in extra]
    if seed is not None:
        extra.append(f"seed={seed}")
        flags.append(f"--seed {seed}")
    return scenario_from_dict(data, str(path), extra, flags)


def catalogue() -> list[str]:
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))
