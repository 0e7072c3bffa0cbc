"""Procedural synthesis of a terrain patch from a :class:`TerrainRecipe` and a seed.

``synthesize`` reads as its layers in order: landforms (regional slope, craters), surface detail (fBm
roughness, sand ripples), the material map (outcrop where the landform is steep), then rocks seated on the
final heights. Every random layer draws from its own generator, derived from ``(seed, layer)``
(:func:`terrains._noise.layer_rng`), so adding or changing one layer never changes another. Height functions
take the grid axes ``xs_m`` (``(ncol,)``) and ``ys_m`` (``(nrow,)``) and return a ``(nrow, ncol)`` array in
the hfield convention of :mod:`terrains.terrain`.
"""

from __future__ import annotations

import math
from dataclasses import replace
from enum import IntEnum

import numpy as np

from terrains._noise import filtered_noise, gaussian_transfer, layer_rng, max_sigma_px, smooth_noise
from terrains.golombek import sample_diameters_m
from terrains.recipe import (
    GENERATED_ROCK_PREFIX,
    Disc,
    ExplicitRockSpec,
    MaterialSpec,
    RockSpec,
    TerrainRecipe,
)
from terrains.rock_shapes import make_irregular
from terrains.terrain import Material, Rock, Terrain, bilinear_sample

#: Extra skirt depth below the lowest ground point under a rock's footprint, so no gap shows on slopes.
EMBED_MARGIN_M = 0.02
#: Points probed on a rock's outline (and again on the half-size outline) to find the lowest ground under it.
SEAT_PROBES = 64
#: Default buried depth of an explicit rock without ``buried_m``, as a fraction of its visible height.
EXPLICIT_BURIED_FRAC = 0.15
#: Attempts to find a free spot for one random rock before it is dropped (dense cover).
PLACEMENT_ATTEMPTS = 64


class Layer(IntEnum):
    """Stable identifiers of the random layers (each generator's ``spawn_key``). Never renumber."""

    ROUGHNESS = 1
    RIPPLES = 2
    MATERIAL = 3
    ROCKS = 4
    IRREGULAR_ROCKS = 8  # which rocks are irregular, their forms and vertices (terrains/rock_shapes.py)


def synthesize(recipe: TerrainRecipe, seed: int) -> Terrain:
    """Build the terrain a recipe describes; the same ``(recipe, seed)`` always gives identical bytes."""
    if seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed}")
    nrow, ncol = recipe.grid_shape
    cell = recipe.cell_size_m
    xs_m = (np.arange(ncol) - 0.5 * (ncol - 1)) * cell
    ys_m = (np.arange(nrow) - 0.5 * (nrow - 1)) * cell

    # landforms: regional slope and craters (their slopes decide where outcrop is exposed)
    landform = np.full((nrow, ncol), recipe.base_height_m, dtype=np.float64)
    landform += planar_slope_m(xs_m, ys_m, recipe.slope.slope_deg, recipe.slope.azimuth_deg)
    for c in recipe.craters:
        landform += crater_bowl_m(
            xs_m,
            ys_m,
            c.center_xy_m,
            c.diameter_m,
            c.depth_to_diameter,
            c.rim_height_frac,
            c.rim_width_frac,
            c.floor_flatness,
        )
    # surface detail: fBm roughness and sand ripples
    heights = landform.copy()
    r = recipe.roughness
    heights += fbm_noise_m(
        (nrow, ncol),
        cell,
        r.rms_m,
        r.correlation_length_m,
        r.octaves,
        r.hurst,
        layer_rng(seed, Layer.ROUGHNESS),
    )
    if recipe.ripples is not None:
        rp = recipe.ripples
        heights += ripples_m(
            xs_m,
            ys_m,
            rp.amplitude_m,
            rp.wavelength_m,
            rp.azimuth_deg,
            rp.sharpness,
            rp.sinuosity,
            layer_rng(seed, Layer.RIPPLES),
        )

    materials = material_map(landform, cell, recipe.material, layer_rng(seed, Layer.MATERIAL))
    for d in recipe.drift_ripples:  # deterministic (no random layer): heights and the drift material
        thickness = drift_ripple_m(xs_m, ys_m, d.x_m, d.y_m, d.height_m, d.width_m, d.length_m, d.azimuth_deg)
        heights += thickness
        materials[thickness >= max(d.drift_min_thickness_m, 1e-9)] = Material.DRIFT

    explicit = [explicit_rock(spec) for spec in recipe.explicit_rocks]
    keep_clear = [Disc(r.x_m, r.y_m, r.footprint_radius_m) for r in explicit]
    half_x, half_y = float(xs_m[-1]), float(ys_m[-1])
    random_rocks = rocks_golombek(half_x, half_y, recipe.rocks, keep_clear, layer_rng(seed, Layer.ROCKS))
    random_rocks = make_irregular(
        random_rocks,
        recipe.rocks.irregular_fraction,
        tuple(recipe.rocks.irregular_forms),
        layer_rng(seed, Layer.IRREGULAR_ROCKS),
    )
    explicit = [
        seat_rock(rock, heights, cell, buried_m=spec.buried_m)
        for rock, spec in zip(explicit, recipe.explicit_rocks, strict=True)
    ]
    rocks = explicit + [seat_rock(rock, heights, cell) for rock in random_rocks]
    return Terrain(
        heights_m=heights, cell_size_m=cell, materials=materials, rocks=rocks, seed=seed, recipe=recipe
    )


# ---------------------------------------------------------------------------------------------- heights


def planar_slope_m(xs_m: np.ndarray, ys_m: np.ndarray, slope_deg: float, azimuth_deg: float) -> np.ndarray:
    """Plane through the origin tilted ``slope_deg``, rising toward ``azimuth_deg`` (from +x toward +y)."""
    az = math.radians(azimuth_deg)
    grade = math.tan(math.radians(slope_deg))
    return grade * (math.cos(az) * xs_m[None, :] + math.sin(az) * ys_m[:, None])


def fbm_noise_m(
    shape: tuple[int, int],
    cell_size_m: float,
    rms_m: float,
    correlation_length_m: float,
    octaves: int,
    hurst: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Fractional-Brownian height noise with RMS exactly ``rms_m`` (zero mean).

    An octave sum of Gaussian-smoothed white noise, done as one filter in the Fourier domain: octave ``o`` has
    scale ``correlation_length_m / 2^o`` (Gaussian sigma) and amplitude ``2^(-o H)``, the self-affine scaling
    of natural terrain (Hurst exponent ``H``; 1 smooth, 0 rough). Octaves finer than half a cell are dropped;
    scales beyond a quarter of the patch are clamped there (the patch is a window on a larger undulation).
    """
    if rms_m == 0.0:
        return np.zeros(shape)
    transfer = np.zeros((shape[0], shape[1] // 2 + 1))
    for o in range(octaves):
        sigma_px = correlation_length_m / 2.0**o / cell_size_m
        if sigma_px < 0.5 and o > 0:
            break
        sigma_px = min(max(sigma_px, 0.5), max_sigma_px(shape))
        unit_std_gain = math.sqrt(4.0 * math.pi) * sigma_px  # white noise smoothed by sigma has std 1/that
        transfer += 2.0 ** (-o * hurst) * unit_std_gain * gaussian_transfer(shape, sigma_px)
    return rms_m * filtered_noise(shape, transfer, rng)


def ripple_profile(phase: np.ndarray, sharpness: float) -> np.ndarray:
    """Asymmetric ripple cross-section in ``[-1, 1]``: trough at phase 0, crest at ``0.5 + 0.3 sharpness``.

    The stoss (upwind) side rises over the first part of the period and the lee side falls over the rest, so a
    sharper ripple has a steeper lee face; raising the crest shape to a power ``1 + 2 sharpness`` narrows the
    crests and widens the troughs, as in aeolian ripples.
    """
    stoss = 0.5 + 0.3 * sharpness
    psi = np.where(phase < stoss, 0.5 * phase / stoss, 0.5 + 0.5 * (phase - stoss) / (1.0 - stoss))
    crest = 0.5 * (1.0 - np.cos(2.0 * np.pi * psi))
    return 2.0 * crest ** (1.0 + 2.0 * sharpness) - 1.0


def ripples_m(
    xs_m: np.ndarray,
    ys_m: np.ndarray,
    amplitude_m: float,
    wavelength_m: float,
    azimuth_deg: float,
    sharpness: float,
    sinuosity: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Parallel sand ripples with crests normal to ``azimuth_deg``, lee faces toward it, random phase.

    ``sinuosity`` bends the crests with a smooth random shift of up to about ``sinuosity * wavelength / 2``.
    """
    az = math.radians(azimuth_deg)
    along = math.cos(az) * xs_m[None, :] + math.sin(az) * ys_m[:, None]
    phase0 = rng.uniform(0.0, 1.0)
    if sinuosity > 0.0:
        cell = float(xs_m[1] - xs_m[0])
        wander = smooth_noise(along.shape, 2.0 * wavelength_m / cell, rng)
        along = along + 0.5 * sinuosity * wavelength_m * wander
    phase = np.mod(along / wavelength_m + phase0, 1.0)
    return amplitude_m * ripple_profile(phase, sharpness)


def drift_ripple_m(
    xs_m: np.ndarray,
    ys_m: np.ndarray,
    x_m: float,
    y_m: float,
    height_m: float,
    width_m: float,
    length_m: float,
    azimuth_deg: float,
) -> np.ndarray:
    """Thickness of one drift ripple (see :class:`terrains.recipe.DriftRippleSpec`): ``height cos^2(pi u / width)``
    across the crest, the crest ``length_m`` long with ends rounded by a ``cos^2`` taper over half a width."""
    az = math.radians(azimuth_deg)
    dx, dy = xs_m[None, :] - x_m, ys_m[:, None] - y_m
    across = math.cos(az) * dx + math.sin(az) * dy
    along = -math.sin(az) * dx + math.cos(az) * dy
    section = np.where(np.abs(across) <= 0.5 * width_m, np.cos(np.pi * across / width_m) ** 2, 0.0)
    taper_m = 0.5 * width_m
    beyond = np.clip(np.abs(along) - (0.5 * length_m - taper_m), 0.0, taper_m) / taper_m  # 0 inside, 1 at the end
    return height_m * section * np.cos(0.5 * np.pi * beyond) ** 2


def crater_profile_m(
    r_m: np.ndarray,
    diameter_m: float,
    depth_to_diameter: float,
    rim_height_frac: float,
    rim_width_frac: float,
    floor_flatness: float,
) -> np.ndarray:
    """Height of a simple crater relative to the pre-impact surface at radius ``r_m`` from its centre.

    Morphology of fresh simple craters (Pike 1977; Melosh 1989): a parabolic bowl, depth from rim crest to
    floor ``depth_to_diameter * D`` (about 0.2 when fresh), a raised rim ``rim_height_frac * D`` (about 0.036
    D) at ``r = R``, and an ejecta blanket thinning as ``(r/R)^-3`` outside (McGetchin et al. 1973). The crest
    is rounded over ``rim_width_frac * R`` on both sides (zero slope at the crest); the rim height and the
    depth are exact. ``floor_flatness`` is the flat floor's radius over ``R``.
    """
    radius = 0.5 * diameter_m
    rho = np.asarray(r_m, dtype=np.float64) / radius
    rim_m = rim_height_frac * diameter_m
    floor_m = rim_m - depth_to_diameter * diameter_m
    width_s = min(rim_width_frac / (1.0 - floor_flatness), 0.95)  # crest rounding in wall coordinates
    s = np.clip((rho - floor_flatness) / (1.0 - floor_flatness), 0.0, 1.0)
    wall = np.where(s <= 1.0 - width_s, s * s / (1.0 - width_s), 1.0 - (1.0 - s) ** 2 / width_s)
    inside = floor_m + (rim_m - floor_m) * wall
    beyond = np.maximum(rho - 1.0, 0.0)
    ejecta = rim_m * np.maximum(rho, 1.0) ** -3 * (1.0 + 3.0 * beyond * np.exp(-beyond / rim_width_frac))
    return np.where(rho <= 1.0, inside, ejecta)


def crater_bowl_m(
    xs_m: np.ndarray,
    ys_m: np.ndarray,
    center_xy_m: tuple[float, float],
    diameter_m: float,
    depth_to_diameter: float,
    rim_height_frac: float,
    rim_width_frac: float,
    floor_flatness: float,
) -> np.ndarray:
    """A crater (see :func:`crater_profile_m`) centred at ``center_xy_m``; the centre may lie off the
    patch."""
    r_m = np.hypot(xs_m[None, :] - center_xy_m[0], ys_m[:, None] - center_xy_m[1])
    return crater_profile_m(
        r_m, diameter_m, depth_to_diameter, rim_height_frac, rim_width_frac, floor_flatness
    )


# -------------------------------------------------------------------------------------------- materials


def material_map(
    landform_m: np.ndarray, cell_size_m: float, spec: MaterialSpec, rng: np.random.Generator
) -> np.ndarray:
    """Material code per cell (``uint8``).

    ``patches``: a smooth random field (Gaussian sigma ``patch_scale_m``) ranked so that exactly
    ``round(bedrock_fraction * cells)`` of the highest cells are bedrock and the next ``mixed_fraction`` are
    mixed (thin sand at the patch edges). Then cells steeper than ``outcrop_slope_deg`` become bedrock.
    """
    shape = landform_m.shape
    uniform = {"sand": Material.SAND, "bedrock": Material.BEDROCK, "mixed": Material.MIXED}
    if spec.kind in uniform:
        materials = np.full(shape, int(uniform[spec.kind]), dtype=np.uint8)
    else:
        field = smooth_noise(shape, spec.patch_scale_m / cell_size_m, rng).ravel()
        order = np.argsort(field, kind="stable")[::-1]
        n_bed = round(spec.bedrock_fraction * field.size)
        n_mixed = min(round(spec.mixed_fraction * field.size), field.size - n_bed)
        flat = np.full(field.size, int(Material.SAND), dtype=np.uint8)
        flat[order[n_bed : n_bed + n_mixed]] = Material.MIXED
        flat[order[:n_bed]] = Material.BEDROCK
        materials = flat.reshape(shape)
    if spec.outcrop_slope_deg is not None:
        dz_dy, dz_dx = np.gradient(landform_m, cell_size_m)
        slope_deg = np.degrees(np.arctan(np.hypot(dz_dx, dz_dy)))
        materials[slope_deg > spec.outcrop_slope_deg] = Material.BEDROCK
    return materials


# ------------------------------------------------------------------------------------------------ rocks


def rocks_golombek(
    half_x_m: float, half_y_m: float, spec: RockSpec, keep_clear: list[Disc], rng: np.random.Generator
) -> list[Rock]:
    """Random rocks on the patch following Golombek & Rapp (1997), not yet seated (``z_base_m = 0``).

    Diameters (footprint-area equivalent) come from ``F_k(D) = k exp(-q(k) D)``, ``q = 1.79 + 0.152 / k``, for
    ``D >= spec.min_diameter_m``; heights are ``D`` times a ratio drawn from ``height_to_diameter`` (about
    0.5, Golombek & Rapp), clipped to ``[min_height_m, max_height_m]``. Positions are uniform, largest rock
    first, each rock's bounding circle kept inside the patch and clear of earlier rocks, of
    ``spec.exclusion_zones`` and of ``keep_clear`` (e.g. explicit rocks); a rock with no free spot after
    ``PLACEMENT_ATTEMPTS`` tries is dropped. ``buried_m`` is set from ``buried_fraction`` (buried / (buried +
    visible)); :func:`seat_rock` deepens it.
    """
    area_m2 = 4.0 * half_x_m * half_y_m
    diameters = sample_diameters_m(spec.cover_fraction, spec.min_diameter_m, area_m2, rng)
    n = len(diameters)
    if n == 0:
        return []
    shapes = [spec.shapes[i] for i in rng.integers(0, len(spec.shapes), n)]
    aspect = rng.uniform(1.0, spec.aspect_ratio_max, n)
    ratio = rng.uniform(*spec.height_to_diameter, n)
    yaw = rng.uniform(0.0, 2.0 * np.pi, n)
    buried_frac = rng.uniform(*spec.buried_fraction, n)
    heights = np.clip(ratio * diameters, spec.min_height_m, spec.max_height_m)

    drafts = [
        _rock_of_diameter(
            shapes[i],
            float(diameters[i]),
            float(aspect[i]),
            float(heights[i]),
            float(yaw[i]),
            float(buried_frac[i]),
        )
        for i in range(n)
    ]
    placer = _DiscPlacer(
        half_x_m, half_y_m, [*spec.exclusion_zones, *keep_clear], max(r.footprint_radius_m for r in drafts)
    )
    rocks: list[Rock] = []
    for draft in drafts:
        xy = placer.place(draft.footprint_radius_m, rng)
        if xy is not None:
            name = f"{GENERATED_ROCK_PREFIX}{len(rocks):04d}"
            rocks.append(replace(draft, x_m=xy[0], y_m=xy[1], name=name))
    return rocks


def _rock_of_diameter(
    shape: str, diameter_m: float, aspect: float, height_m: float, yaw_rad: float, buried_frac: float
) -> Rock:
    """A rock at the origin whose footprint area equals that of a disc of ``diameter_m``."""
    if shape == "hemispheroid":
        aspect = 1.0
    # footprint area: ellipse pi L W / 4, triangle L W / 2; both set to pi D^2 / 4
    area_lw = diameter_m**2 if shape != "tetrahedron" else 0.5 * math.pi * diameter_m**2
    length = math.sqrt(area_lw * aspect)
    width = length if shape == "hemispheroid" else math.sqrt(area_lw / aspect)
    buried = buried_frac / (1.0 - buried_frac) * height_m
    return Rock(0.0, 0.0, 0.0, shape, length, width, height_m, yaw_rad, buried)  # type: ignore[arg-type]


class _DiscPlacer:
    """Random sequential placement of non-overlapping discs, with a bucket grid for the overlap tests."""

    def __init__(self, half_x_m: float, half_y_m: float, keep_clear: list[Disc], max_radius_m: float) -> None:
        self.half_x, self.half_y = half_x_m, half_y_m
        self.zones = np.array([[z.x_m, z.y_m, z.radius_m] for z in keep_clear]).reshape(-1, 3)
        self.bucket_m = 2.0 * max_radius_m + 1e-6
        self.buckets: dict[tuple[int, int], list[int]] = {}
        self.discs: list[tuple[float, float, float]] = []

    def place(self, radius_m: float, rng: np.random.Generator) -> tuple[float, float] | None:
        lim_x, lim_y = self.half_x - radius_m, self.half_y - radius_m
        if lim_x < 0.0 or lim_y < 0.0:
            return None
        for _ in range(PLACEMENT_ATTEMPTS):
            x, y = float(rng.uniform(-lim_x, lim_x)), float(rng.uniform(-lim_y, lim_y))
            if self._free(x, y, radius_m):
                self._add(x, y, radius_m)
                return x, y
        return None

    def _key(self, x: float, y: float) -> tuple[int, int]:
        return math.floor(x / self.bucket_m), math.floor(y / self.bucket_m)

    def _free(self, x: float, y: float, r: float) -> bool:
        if len(self.zones):
            d = np.hypot(self.zones[:, 0] - x, self.zones[:, 1] - y)
            if np.any(d < self.zones[:, 2] + r):
                return False
        bi, bj = self._key(x, y)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                for k in self.buckets.get((bi + di, bj + dj), ()):
                    ox, oy, orad = self.discs[k]
                    if (ox - x) ** 2 + (oy - y) ** 2 < (orad + r) ** 2:
                        return False
        return True

    def _add(self, x: float, y: float, r: float) -> None:
        self.buckets.setdefault(self._key(x, y), []).append(len(self.discs))
        self.discs.append((x, y, r))


def explicit_rock(spec: ExplicitRockSpec) -> Rock:
    """The rock an :class:`ExplicitRockSpec` names, not yet seated (``z_base_m = 0``).

    Without ``buried_m`` in the spec, the skirt starts at ``EXPLICIT_BURIED_FRAC`` of the height (deepened by
    :func:`seat_rock` on slopes).
    """
    return Rock(
        x_m=spec.x_m,
        y_m=spec.y_m,
        z_base_m=0.0,
        shape=spec.shape,
        length_m=spec.length_m,
        width_m=spec.width_m,
        height_m=spec.height_m,
        yaw_rad=math.radians(spec.yaw_deg),
        buried_m=EXPLICIT_BURIED_FRAC * spec.height_m if spec.buried_m is None else spec.buried_m,
        name=spec.name,
    )


def seat_rock(rock: Rock, heights_m: np.ndarray, cell_size_m: float, buried_m: float | None = None) -> Rock:
    """Put a rock on the ground: ``z_base_m`` from the heights at its centre, skirt deep enough to hide gaps.

    With ``buried_m`` given, that depth is used as is (an explicit choice). Otherwise the skirt is the rock's
    own ``buried_m``, deepened if needed to reach ``EMBED_MARGIN_M`` below the lowest ground under the
    footprint (probed on the outline and the half-size outline), so the rock sits flush on slopes and rough
    ground.
    """
    z_base = float(bilinear_sample(heights_m, cell_size_m, np.float64(rock.x_m), np.float64(rock.y_m)))
    if buried_m is not None:
        return replace(rock, z_base_m=z_base, buried_m=float(buried_m))
    outline = rock.footprint_xy_m(SEAT_PROBES)
    centre = np.array([rock.x_m, rock.y_m])
    probes = np.vstack([outline, centre + 0.5 * (outline - centre)])
    ground = bilinear_sample(heights_m, cell_size_m, probes[:, 0], probes[:, 1])
    needed = max(0.0, z_base - float(ground.min())) + EMBED_MARGIN_M
    return replace(rock, z_base_m=z_base, buried_m=max(rock.buried_m, needed))
