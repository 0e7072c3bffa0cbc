"""Typed description of a terrain patch: the input of :func:`terrains.synthesize`.

A recipe plus a seed fully determines a :class:`terrains.Terrain`. All models are pydantic v2, frozen, with
``extra="forbid"`` so a misspelt key is an error rather than a silently ignored setting; out-of-range values
raise a :class:`pydantic.ValidationError` whose location names the field (e.g. ``slope.slope_deg``).

Frame: world x east, y north, z up; the patch is centred on the origin. Angles called ``azimuth_deg`` are
measured from +x toward +y (counter-clockwise seen from above).

Physical anchors used for ranges and defaults (see ``/work/shared/REFERENCE.md``):

* slopes up to about 31 deg were driven on Mars; the range stops at 45 deg (beyond the angle of repose of
  sand);
* craters: Eagle about 20 m, Endurance about 130 m in diameter; fresh simple craters have depth/diameter about
  0.2 (Pike 1977: d = 0.196 D, rim height 0.036 D);
* rocks follow Golombek & Rapp (1997), cumulative fractional area ``F_k(D) = k exp(-q(k) D)``,
  ``q(k) = 1.79 + 0.152 / k``; rocks up to 1.5 m (Wopmay: 0.6 m tall, 0.9 m wide, 1.5 m long).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal, NamedTuple

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from terrains.golombek import cumulative_number_per_m2

RockShape = Literal["hemispheroid", "semi_ellipsoid", "cone", "tetrahedron"]
"""The four analytic rock models of Li et al., "Automation of ground image based Mars rover localization"."""

ROCK_SHAPES: tuple[RockShape, ...] = ("hemispheroid", "semi_ellipsoid", "cone", "tetrahedron")

MaterialKind = Literal["sand", "bedrock", "mixed", "patches"]

#: Largest grid the synthesiser accepts (cells per side ~4097, ~134 MB of float64 heights).
MAX_GRID_CELLS = 4097 * 4097
#: Largest expected number of random rocks (each becomes a MuJoCo geom).
MAX_EXPECTED_ROCKS = 20_000
#: Prefix of generated rock names (``rock_0000``, ...); explicit rocks may not use it.
GENERATED_ROCK_PREFIX = "rock_"

_Metres = Annotated[float, Field(gt=0.0, le=2000.0)]


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, validate_default=True)


class Disc(NamedTuple):
    """A circle on the ground, ``(x_m, y_m, radius_m)``; given as a 3-tuple or list in recipes."""

    x_m: float
    y_m: float
    radius_m: float


class SlopeSpec(_Spec):
    """A planar regional tilt added to the whole patch."""

    slope_deg: float = Field(
        0.0, ge=0.0, le=45.0, description="Tilt of the plane in degrees (Mars drives: <= 31)."
    )
    azimuth_deg: float = Field(
        0.0,
        ge=-360.0,
        le=360.0,
        description="Direction of steepest ascent, degrees from +x toward +y (0: uphill is east, 90: north).",
    )


class RoughnessSpec(_Spec):
    """Fractional-Brownian (fBm) height noise, the small-scale unevenness of the ground."""

    rms_m: float = Field(0.02, ge=0.0, le=0.5, description="Standard deviation of the noise heights, metres.")
    correlation_length_m: float = Field(
        2.0,
        gt=0.0,
        le=1000.0,
        description="Largest feature scale (Gaussian sigma of the coarsest octave), metres.",
    )
    octaves: int = Field(5, ge=1, le=8, description="Number of octaves, each half the scale of the previous.")
    hurst: float = Field(
        0.8, ge=0.0, le=1.0, description="Hurst exponent: octave amplitude ~ scale^H (1 smooth, 0 rough)."
    )


class RippleSpec(_Spec):
    """Aeolian sand ripples: parallel, asymmetric crests (gentle stoss side, steep lee side).

    Erebus ripples (Opportunity) were tens of centimetres high with metres of spacing; the flat-ripple slip of
    44.5 % tripped the 40 % slip limit.
    """

    amplitude_m: float = Field(
        0.1,
        ge=0.0,
        le=2.0,
        description="Half the crest-to-trough height, metres (crest-to-trough = 2 x this).",
    )
    wavelength_m: float = Field(3.0, gt=0.05, le=100.0, description="Crest spacing, metres.")
    azimuth_deg: float = Field(
        0.0,
        ge=-360.0,
        le=360.0,
        description="Direction the wind blows toward (across the crests); lee faces look this way.",
    )
    sharpness: float = Field(
        0.5, ge=0.0, le=1.0, description="0: sinusoid; 1: sharp crests, broad troughs, strongly asymmetric."
    )
    sinuosity: float = Field(
        0.0,
        ge=0.0,
        le=1.0,
        description="Crest wander, as a fraction of half a wavelength (0: straight crests).",
    )


class DriftRippleSpec(_Spec):
    """One ripple of loose, fine-grained drift on the ground (Opportunity's Purgatory ripple, Sol 446: about 30 cm
    tall, a few metres wide, on the flat Meridiani plains).

    Cross-section ``height_m cos^2(pi u / width_m)`` for ``|u| <= width_m / 2`` (``u`` along ``azimuth_deg``, across
    the crest; symmetric, steepest flank ``atan(pi height / width)``), the crest ``length_m`` long with its ends
    rounded over half a width. Cells where the drift is at least ``drift_min_thickness_m`` thick are
    ``Material.DRIFT``; its thin margins count as the ground beneath (a wheel there sinks into the ground, not the
    drift). Drift is a soil of the experimental Wong-Reece law only (``rover_sim/sim/terramechanics_wr.py``).
    """

    x_m: float = Field(ge=-1.0e4, le=1.0e4, description="Crest centre, east, metres.")
    y_m: float = Field(ge=-1.0e4, le=1.0e4, description="Crest centre, north, metres.")
    height_m: float = Field(0.3, gt=0.0, le=2.0, description="Crest height above the ground, metres.")
    width_m: float = Field(3.0, gt=0.1, le=50.0, description="Base width across the crest, metres.")
    length_m: float = Field(10.0, gt=0.1, le=200.0, description="Crest length, metres.")
    azimuth_deg: float = Field(
        0.0, ge=-360.0, le=360.0, description="Direction across the crest (from +x toward +y)."
    )
    drift_min_thickness_m: float = Field(
        0.05, ge=0.0, le=2.0, description="Drift at least this thick is Material.DRIFT; thinner is the ground."
    )


class CraterSpec(_Spec):
    """A simple (bowl-shaped) impact crater.

    Depth is measured from the rim crest to the floor (Pike 1977 convention); fresh simple craters have
    ``depth_to_diameter`` about 0.2 (Eagle about 20 m, Endurance about 130 m across, both degraded to
    shallower bowls). If the crater is larger than the patch, the patch is a local window of the bowl: put
    ``center_xy_m`` outside the patch to sit on the wall.
    """

    center_xy_m: tuple[float, float] = Field(
        (0.0, 0.0), description="Crater centre in the patch frame, metres."
    )
    diameter_m: float = Field(20.0, ge=1.0, le=2000.0, description="Rim-crest diameter D, metres.")
    depth_to_diameter: float = Field(
        0.2, ge=0.05, le=0.3, description="Rim-to-floor depth over diameter (fresh simple crater: about 0.2)."
    )
    rim_height_frac: float = Field(
        0.036, ge=0.0, le=0.1, description="Rim height above the surroundings over diameter (Pike: 0.036)."
    )
    rim_width_frac: float = Field(
        0.1, gt=0.0, le=0.5, description="Width of the rounded rim crest as a fraction of the radius."
    )
    floor_flatness: float = Field(
        0.0, ge=0.0, le=0.8, description="Radius of the flat floor as a fraction of the crater radius."
    )

    @field_validator("center_xy_m")
    @classmethod
    def _centre_in_reach(cls, v: tuple[float, float]) -> tuple[float, float]:
        if max(abs(v[0]), abs(v[1])) > 1.0e4:
            raise ValueError("center_xy_m must be within 10 km of the patch centre")
        return v


class RockSpec(_Spec):
    """Random rocks following the Golombek & Rapp (1997) size-frequency law.

    ``cover_fraction`` is ``k``, the fraction of the ground covered by all rocks; rocks of equivalent
    (footprint area) diameter D or larger cover ``k exp(-q(k) D)``. Only rocks at least ``min_height_m`` tall
    (diameter at least ``min_height_m / mean(height_to_diameter)``) become geoms; smaller ones are left to the
    roughness noise.
    """

    cover_fraction: float = Field(
        0.05,
        ge=0.0,
        le=0.5,
        description="Golombek-Rapp k: total fractional area covered by rocks (VL1 ~0.07).",
    )
    min_height_m: float = Field(
        0.1, gt=0.0, le=1.5, description="Rocks lower than this are not generated (keeps geom counts low)."
    )
    max_height_m: float = Field(1.5, gt=0.0, le=1.5, description="Taller rocks are flattened to this height.")
    height_to_diameter: tuple[float, float] = Field(
        (0.4, 0.6), description="Range of height/diameter ratios (Golombek & Rapp: heights about 0.5 D)."
    )
    aspect_ratio_max: float = Field(
        1.5,
        ge=1.0,
        le=4.0,
        description="Largest length/width ratio of a footprint (hemispheroids are round).",
    )
    shapes: list[RockShape] = Field(
        default_factory=lambda: list(ROCK_SHAPES),
        min_length=1,
        description="Shapes drawn uniformly; repeat a name to weight it.",
    )
    buried_fraction: tuple[float, float] = Field(
        (0.1, 0.3), description="Range of buried depth over total (buried + visible) rock height."
    )
    irregular_fraction: float = Field(
        0.0,
        ge=0.0,
        le=1.0,
        description="Fraction of random rocks drawn as irregular (terrains/rock_shapes.py) instead of analytic.",
    )
    irregular_forms: list[Literal["irregular_hull", "angular_block", "slab"]] = Field(
        default_factory=lambda: ["irregular_hull", "angular_block", "slab"],
        min_length=1,
        description="Irregular forms drawn uniformly (noise-displaced hull, angular block, flat slab).",
    )
    exclusion_zones: list[Disc] = Field(
        default_factory=lambda: [Disc(0.0, 0.0, 1.5)],
        description="Discs (x_m, y_m, radius_m) free of random rocks; the default clears the rover start.",
    )

    @field_validator("height_to_diameter")
    @classmethod
    def _ratio_range(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = v
        if not (0.1 <= lo <= hi <= 1.5):
            raise ValueError("height_to_diameter must be (lo, hi) with 0.1 <= lo <= hi <= 1.5")
        return v

    @field_validator("buried_fraction")
    @classmethod
    def _buried_range(cls, v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = v
        if not (0.0 <= lo <= hi <= 0.8):
            raise ValueError("buried_fraction must be (lo, hi) with 0 <= lo <= hi <= 0.8")
        return v

    @field_validator("exclusion_zones")
    @classmethod
    def _positive_radii(cls, v: list[Disc]) -> list[Disc]:
        for zone in v:
            if not (zone.radius_m > 0.0 and math.isfinite(zone.x_m) and math.isfinite(zone.y_m)):
                raise ValueError(f"exclusion zone {tuple(zone)} needs finite x_m, y_m and radius_m > 0")
        return v

    @property
    def min_diameter_m(self) -> float:
        """Smallest generated diameter: ``min_height_m`` over the mean height/diameter ratio."""
        return self.min_height_m / (0.5 * (self.height_to_diameter[0] + self.height_to_diameter[1]))

    def expected_count(self, area_m2: float) -> float:
        """Mean number of random rocks on ``area_m2`` (Golombek-Rapp, diameters >= ``min_diameter_m``)."""
        return float(cumulative_number_per_m2(self.min_diameter_m, self.cover_fraction)) * area_m2

    @model_validator(mode="after")
    def _height_order(self) -> RockSpec:
        if self.min_height_m > self.max_height_m:
            raise ValueError(
                f"min_height_m ({self.min_height_m}) must not exceed max_height_m ({self.max_height_m})"
            )
        return self


class ExplicitRockSpec(_Spec):
    """One named rock placed by hand (e.g. Wopmay: 1.5 m long, 0.9 m wide, 0.6 m tall)."""

    name: str = Field(
        min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$", description="Unique rock name."
    )
    x_m: float = Field(ge=-1.0e4, le=1.0e4, description="Centre east coordinate, metres.")
    y_m: float = Field(ge=-1.0e4, le=1.0e4, description="Centre north coordinate, metres.")
    shape: RockShape = "semi_ellipsoid"
    length_m: float = Field(gt=0.0, le=5.0, description="Footprint extent along the rock's own x, metres.")
    width_m: float = Field(gt=0.0, le=5.0, description="Footprint extent along the rock's own y, metres.")
    height_m: float = Field(
        gt=0.0, le=3.0, description="Visible height above the ground at the centre, metres."
    )
    yaw_deg: float = Field(
        0.0, ge=-360.0, le=360.0, description="Rotation of the rock's x axis from world +x."
    )
    buried_m: float | None = Field(
        None,
        ge=0.0,
        le=3.0,
        description="Depth below ground; None: deep enough to sit flush on the local slope.",
    )

    @field_validator("name")
    @classmethod
    def _not_reserved(cls, v: str) -> str:
        if v.startswith(GENERATED_ROCK_PREFIX):
            raise ValueError(
                f"names starting with {GENERATED_ROCK_PREFIX!r} are reserved for generated rocks"
            )
        return v

    @model_validator(mode="after")
    def _round_hemispheroid(self) -> ExplicitRockSpec:
        if self.shape == "hemispheroid" and not math.isclose(self.length_m, self.width_m, rel_tol=1e-9):
            raise ValueError(
                "a hemispheroid has a round footprint: set length_m == width_m or use semi_ellipsoid"
            )
        return self


class MaterialSpec(_Spec):
    """Ground material map: loose sand, bedrock outcrop, or mixed (thin sand over rock, or gravel).

    ``patches`` thresholds a smooth random field (correlation ``patch_scale_m``) so that ``bedrock_fraction``
    of the cells are bedrock and a band of ``mixed_fraction`` around the patch edges is mixed. Independently
    of ``kind``, cells where the landform (regional slope plus craters; ripples and roughness do not count) is
    steeper than ``outcrop_slope_deg`` become bedrock (steep crater walls are outcrop, as in Endurance).
    """

    kind: MaterialKind = "sand"
    bedrock_fraction: float = Field(
        0.3, ge=0.0, le=1.0, description="Fraction of cells that are bedrock (patches)."
    )
    mixed_fraction: float = Field(
        0.1, ge=0.0, le=1.0, description="Fraction of cells that are mixed, at patch edges (patches)."
    )
    patch_scale_m: float = Field(
        3.0, gt=0.0, le=1000.0, description="Correlation length of the patches, metres."
    )
    outcrop_slope_deg: float | None = Field(
        None, gt=0.0, le=90.0, description="Cells steeper than this become bedrock; None disables."
    )

    @model_validator(mode="after")
    def _fractions_sum(self) -> MaterialSpec:
        if self.bedrock_fraction + self.mixed_fraction > 1.0 + 1e-12:
            raise ValueError(
                f"bedrock_fraction + mixed_fraction = {self.bedrock_fraction + self.mixed_fraction} exceeds 1"
            )
        return self


class StreamSpec(_Spec):
    """``[terrain.streamed]``: synthesise the site tile by tile around the rover (see :mod:`terrains.stream`).

    The physics heightfield and the render model then cover ``window_tiles`` x ``window_tiles`` tiles around
    the rover's tile and move with it; ``size_m`` is ignored. Landforms beyond the recipe's slope, roughness,
    explicit craters and rocks: hills and random degraded craters (up to Endurance's 130 m).
    """

    tile_m: float = Field(8.0, ge=2.0, le=50.0, description="Tile side, metres (rounded to whole cells).")
    window_tiles: int = Field(3, ge=3, le=9, description="Window side in tiles (odd): the rover's tile +- k//2.")
    rock_slots: int = Field(800, ge=16, le=5000, description="Most rocks a window holds (primitive geom pool).")
    hill_amplitude_m: float = Field(0.0, ge=0.0, le=20.0, description="Std of the hills' height, metres.")
    hill_wavelength_m: float = Field(80.0, ge=10.0, le=2000.0, description="Hill spacing, metres.")
    crater_density_per_km2: float = Field(0.0, ge=0.0, le=200.0, description="Random craters per km^2.")
    crater_min_diameter_m: float = Field(10.0, ge=2.0, le=130.0)
    crater_max_diameter_m: float = Field(130.0, ge=2.0, le=130.0, description="Endurance is about 130 m.")
    crater_depth_to_diameter: float = Field(0.08, ge=0.05, le=0.3, description="Degraded bowls: shallower.")
    crater_rim_height_frac: float = Field(0.02, ge=0.0, le=0.1)
    crater_free_zones: list[Disc] = Field(default_factory=list, max_length=200,
                                          description="No random crater reaches into these discs (the route).")

    @field_validator("window_tiles")
    @classmethod
    def _odd(cls, v: int) -> int:
        if v % 2 == 0:
            raise ValueError(f"window_tiles must be odd (3, 5, 7, 9), got {v}")
        return v

    @model_validator(mode="after")
    def _diameters(self) -> StreamSpec:
        if self.crater_min_diameter_m > self.crater_max_diameter_m:
            raise ValueError("crater_min_diameter_m must be <= crater_max_diameter_m")
        return self


class TerrainRecipe(_Spec):
    """Everything that shapes a terrain patch; ``synthesize(recipe, seed)`` turns it into a :class:`Terrain`.

    The grid has ``round(size_m[0] / cell_size_m) + 1`` columns and ``round(size_m[1] / cell_size_m) + 1``
    rows, so the realised extent is a whole number of cells (it equals ``size_m`` when the size is a multiple
    of the cell).
    """

    size_m: tuple[_Metres, _Metres] = Field((20.0, 20.0), description="Patch extent (east, north), metres.")
    cell_size_m: float = Field(0.05, ge=0.01, le=2.0, description="Grid spacing, metres.")
    base_height_m: float = Field(0.0, ge=-1.0e4, le=1.0e4, description="Height added everywhere, metres.")
    slope: SlopeSpec = Field(default_factory=SlopeSpec)
    roughness: RoughnessSpec = Field(default_factory=RoughnessSpec)
    ripples: RippleSpec | None = None
    drift_ripples: list[DriftRippleSpec] = Field(
        default_factory=list, max_length=100, description="Single ripples of loose drift (Purgatory)."
    )
    craters: list[CraterSpec] = Field(default_factory=list)
    rocks: RockSpec = Field(default_factory=RockSpec)
    explicit_rocks: list[ExplicitRockSpec] = Field(default_factory=list)
    material: MaterialSpec = Field(default_factory=MaterialSpec)
    streamed: StreamSpec | None = Field(None, description="Stream the site tile by tile (large sites).")

    @property
    def grid_shape(self) -> tuple[int, int]:
        """``(nrow, ncol)`` of the heightfield this recipe produces."""
        ncol = round(self.size_m[0] / self.cell_size_m) + 1
        nrow = round(self.size_m[1] / self.cell_size_m) + 1
        return nrow, ncol

    @model_validator(mode="after")
    def _grid_and_rocks(self) -> TerrainRecipe:
        nrow, ncol = self.grid_shape
        if nrow < 3 or ncol < 3:
            raise ValueError(
                f"size_m {self.size_m} gives a {nrow} x {ncol} grid at cell_size_m {self.cell_size_m}; "
                "make the patch at least 2 cells across"
            )
        if nrow * ncol > MAX_GRID_CELLS:
            raise ValueError(
                f"size_m {self.size_m} at cell_size_m {self.cell_size_m} gives {nrow} x {ncol} cells "
                f"(more than {MAX_GRID_CELLS}); use a larger cell_size_m or a smaller patch"
            )
        half_x = (ncol - 1) * self.cell_size_m / 2.0
        half_y = (nrow - 1) * self.cell_size_m / 2.0
        expected = self.rocks.expected_count(4.0 * half_x * half_y)
        if expected > MAX_EXPECTED_ROCKS:
            raise ValueError(
                f"rocks: about {expected:.0f} rocks expected (limit {MAX_EXPECTED_ROCKS}); raise "
                "rocks.min_height_m, lower rocks.cover_fraction or shrink the patch"
            )
        for k, d in enumerate(self.drift_ripples):
            if abs(d.x_m) > half_x or abs(d.y_m) > half_y:
                raise ValueError(
                    f"drift_ripples.{k}: crest centre ({d.x_m}, {d.y_m}) lies outside the patch "
                    f"(|x| <= {half_x}, |y| <= {half_y})"
                )
        names: set[str] = set()
        for rock in self.explicit_rocks:
            if rock.name in names:
                raise ValueError(f"explicit_rocks: duplicate rock name {rock.name!r}")
            names.add(rock.name)
            if abs(rock.x_m) > half_x or abs(rock.y_m) > half_y:
                raise ValueError(
                    f"explicit_rocks: {rock.name!r} at ({rock.x_m}, {rock.y_m}) lies outside the patch "
                    f"(|x| <= {half_x}, |y| <= {half_y})"
                )
        return self
