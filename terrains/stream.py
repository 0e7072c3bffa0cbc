"""Streamed terrain: a site of any size synthesised tile by tile from world coordinates (``[terrain.streamed]``).

Every layer is a function of world ``(x, y)`` and the seed only, so tiles join without seams and the same tile
comes back byte-identical whenever it is rebuilt:

* landforms: the regional slope (``recipe.slope``), hills (value noise of ``hill_wavelength_m``), the recipe's
  explicit craters and random degraded simple craters up to Endurance's 130 m (Pike 1977 profile,
  :func:`terrains.synth.crater_profile_m`), drawn per 4 * D_max square cell with a per-cell generator;
* detail: fBm value noise with the recipe's roughness rms, correlation length, octaves and Hurst exponent;
* rocks: Golombek & Rapp (1997) diameters per tile (:func:`terrains.golombek.sample_diameters_m`), placed
  from a generator keyed on ``(seed, tile index)``; only ellipsoidal shapes (a streamed rock is a primitive
  geom whose size can change in place, see ``rover_sim/sim/stream.py``);
* albedo: a function of world coordinates, so a window's texture agrees with the next: the multi-scale regolith
  (:func:`terrains.regolith.albedo_tile`, relief shaded for a given sun) or the classic fBm :func:`albedo_world`.

:class:`StreamedSite` hands out :class:`TerrainTile` objects (cached, LRU) and assembles a
:class:`WindowTerrain` (a :class:`Terrain` whose grid is centred on ``origin_xy_m`` instead of the world
origin) of ``window_tiles`` x ``window_tiles`` tiles around a centre tile.
"""

from __future__ import annotations

import hashlib
import math
from collections import OrderedDict
from dataclasses import dataclass, replace
from functools import cache

import numpy as np

from terrains.golombek import sample_diameters_m
from terrains.recipe import CraterSpec, StreamSpec, TerrainRecipe
from terrains.regolith import albedo_tile as regolith_tile
from terrains.synth import crater_profile_m
from terrains.terrain import Material, Rock, Terrain

_MASK64 = np.uint64(0xFFFFFFFFFFFFFFFF)
_INDEX_OFFSET = 1 << 30  # tile and crater-cell indices are shifted non-negative for SeedSequence spawn keys
LAYER_HILLS, LAYER_ROUGH, LAYER_CRATERS, LAYER_ROCKS, LAYER_ALBEDO = 101, 102, 103, 104, 105
EJECTA_FADE = (2.0, 4.0)  # crater ejecta fades to zero between these multiples of the radius (no seam at cut-off)
STREAM_ROCK_SHAPES = ("hemispheroid", "semi_ellipsoid")  # ellipsoids: primitive geoms resized in place
ALBEDO_MEAN, ALBEDO_STD = 0.55, 0.07  # relative albedo of Gusev/Meridiani soil speckle (arbitrary units)


# ------------------------------------------------------------------------------------------------ noise


def _mix64(v: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser: a well-mixed 64-bit hash of each element (uint64 arithmetic wraps)."""
    v = (v ^ (v >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    v = (v ^ (v >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return v ^ (v >> np.uint64(31))


def lattice_uniform(ix: np.ndarray, iy: np.ndarray, seed: int, layer: int) -> np.ndarray:
    """Uniform [-1, 1) value at integer lattice points, deterministic in ``(ix, iy, seed, layer)``."""
    with np.errstate(over="ignore"):
        key = np.uint64((int(seed) * 0x9E3779B1 + layer * 0x85EBCA77) & 0xFFFFFFFFFFFFFFFF)
        h = _mix64(ix.astype(np.int64).view(np.uint64) * np.uint64(0x9E3779B97F4A7C15) ^ key)
        h = _mix64(h ^ iy.astype(np.int64).view(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F))
    return (h >> np.uint64(11)).astype(np.float64) * (2.0 / 2**53) - 1.0


def value_noise(x_m: np.ndarray, y_m: np.ndarray, wavelength_m: float, seed: int, layer: int) -> np.ndarray:
    """Quintic-interpolated lattice noise of world coordinates (lattice spacing ``wavelength_m``), unit std."""
    fx, fy = np.asarray(x_m, dtype=np.float64) / wavelength_m, np.asarray(y_m, dtype=np.float64) / wavelength_m
    x0, y0 = np.floor(fx), np.floor(fy)
    tx, ty = fx - x0, fy - y0
    sx = tx * tx * tx * (tx * (6.0 * tx - 15.0) + 10.0)
    sy = ty * ty * ty * (ty * (6.0 * ty - 15.0) + 10.0)
    ix, iy = x0.astype(np.int64), y0.astype(np.int64)
    v00 = lattice_uniform(ix, iy, seed, layer)
    v10 = lattice_uniform(ix + 1, iy, seed, layer)
    v01 = lattice_uniform(ix, iy + 1, seed, layer)
    v11 = lattice_uniform(ix + 1, iy + 1, seed, layer)
    v = (v00 * (1 - sx) + v10 * sx) * (1 - sy) + (v01 * (1 - sx) + v11 * sx) * sy
    return v / _value_noise_std()


@cache
def _value_noise_std() -> float:
    """Std of raw value noise (lattice uniform [-1, 1), quintic blend), measured once on a fixed sample."""
    g = np.linspace(0.0, 200.0, 801)
    fx, fy = np.meshgrid(g, g)
    x0, y0 = np.floor(fx), np.floor(fy)
    tx, ty = fx - x0, fy - y0
    sx = tx**3 * (tx * (6 * tx - 15) + 10)
    sy = ty**3 * (ty * (6 * ty - 15) + 10)
    ix, iy = x0.astype(np.int64), y0.astype(np.int64)
    v = (lattice_uniform(ix, iy, 0, 0) * (1 - sx) + lattice_uniform(ix + 1, iy, 0, 0) * sx) * (1 - sy) + (
        lattice_uniform(ix, iy + 1, 0, 0) * (1 - sx) + lattice_uniform(ix + 1, iy + 1, 0, 0) * sx
    ) * sy
    return float(v.std())


def fbm_world_m(
    x_m: np.ndarray, y_m: np.ndarray, rms_m: float, corr_m: float, octaves: int, hurst: float, seed: int, layer: int
) -> np.ndarray:
    """Fractional Brownian noise of world coordinates: octave ``k`` has wavelength ``corr_m / 2**k`` and
    amplitude ``2**(-hurst k)``; scaled so the sum has std ``rms_m`` (octaves independent)."""
    amps = 2.0 ** (-hurst * np.arange(octaves))
    out = np.zeros(np.broadcast(x_m, y_m).shape)
    for k, a in enumerate(amps):
        out += a * value_noise(x_m, y_m, corr_m / 2.0**k, seed, layer * 16 + k)
    return out * (rms_m / float(np.sqrt((amps**2).sum())))


def albedo_world(x_m: np.ndarray, y_m: np.ndarray, seed: int, contrast: float = 1.0) -> np.ndarray:
    """Relative ground albedo at world points (float32 in [0, 1]): speckle and mottling as fBm of world
    coordinates, so any window of the site gets the same texels. One function for the lead to swap for the
    imaging branch's ``albedo_tile``."""
    a = ALBEDO_MEAN + contrast * fbm_world_m(x_m, y_m, ALBEDO_STD, 1.2, 6, 0.35, seed, LAYER_ALBEDO)
    return np.clip(a, 0.0, 1.0).astype(np.float32)


def _rng(seed: int, *key: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=tuple(int(k) for k in key)))


# ---------------------------------------------------------------------------------------------- relief


@dataclass(frozen=True)
class _Crater:
    x_m: float
    y_m: float
    spec: CraterSpec


def random_craters(stream: StreamSpec, seed: int, cx: int, cy: int) -> list[_Crater]:
    """The random craters centred in crater cell ``(cx, cy)`` (side ``4 * crater_max_diameter_m``); diameters
    follow a cumulative ``N(>D) ~ D^-2`` law between the min and max diameters."""
    if stream.crater_density_per_km2 <= 0.0:
        return []
    side = 4.0 * stream.crater_max_diameter_m
    rng = _rng(seed, LAYER_CRATERS, cx + _INDEX_OFFSET, cy + _INDEX_OFFSET)
    n = int(rng.poisson(stream.crater_density_per_km2 * side * side / 1e6))
    d_lo, d_hi = stream.crater_min_diameter_m, stream.crater_max_diameter_m
    u = rng.uniform(0.0, 1.0, n)
    diam = 1.0 / np.sqrt(d_lo**-2 - u * (d_lo**-2 - d_hi**-2))  # inverse of the truncated D^-2 tail
    xy = (np.array([cx, cy]) + rng.uniform(0.0, 1.0, (n, 2))) * side
    out = []
    for (x, y), d in zip(xy, diam, strict=True):
        if any(math.hypot(x - z.x_m, y - z.y_m) < z.radius_m + d for z in stream.crater_free_zones):
            continue
        spec = CraterSpec(diameter_m=float(d), depth_to_diameter=stream.crater_depth_to_diameter,
                          rim_height_frac=stream.crater_rim_height_frac)  # fmt: skip
        out.append(_Crater(float(x), float(y), spec))
    return out


def crater_relief_m(x_m: np.ndarray, y_m: np.ndarray, craters: list[_Crater]) -> np.ndarray:
    """Sum of crater profiles, ejecta faded to zero between ``EJECTA_FADE`` radii (continuous everywhere)."""
    out = np.zeros(np.broadcast(x_m, y_m).shape)
    for c in craters:
        s = c.spec
        r = np.hypot(x_m - c.x_m, y_m - c.y_m)
        radius = 0.5 * s.diameter_m
        near = r < EJECTA_FADE[1] * radius
        if not near.any():
            continue
        prof = crater_profile_m(r[near], s.diameter_m, s.depth_to_diameter, s.rim_height_frac, s.rim_width_frac,
                                s.floor_flatness)  # fmt: skip
        t = np.clip((r[near] / radius - EJECTA_FADE[0]) / (EJECTA_FADE[1] - EJECTA_FADE[0]), 0.0, 1.0)
        out[near] += prof * (1.0 - t * t * (3.0 - 2.0 * t))
    return out


# ------------------------------------------------------------------------------------------------ tiles


@dataclass(frozen=True)
class TerrainTile:
    """One square tile: grid points ``x = (j0 + j) * cell``, ``y = (i0 + i) * cell`` for ``i, j < n``."""

    index: tuple[int, int]  # (tile column tx, tile row ty)
    heights_m: np.ndarray  # (n, n) float64, row = y
    rocks: tuple[Rock, ...]

    def digest(self) -> str:
        """SHA-256 of the heights and rocks: equal digests mean byte-identical tiles."""
        h = hashlib.sha256(np.ascontiguousarray(self.heights_m).tobytes())
        h.update(repr(self.rocks).encode())
        return h.hexdigest()


@dataclass(eq=False)
class WindowTerrain(Terrain):
    """A :class:`Terrain` whose centred grid sits at ``(origin_x_m, origin_y_m)`` in the world (a window of a
    streamed site). Queries take world coordinates; ``xs_m``/``ys_m`` are world coordinates."""

    origin_x_m: float = 0.0
    origin_y_m: float = 0.0
    window_index: tuple[int, int] = (0, 0)  # centre tile of the window

    @property
    def origin_xy_m(self) -> tuple[float, float]:
        return (self.origin_x_m, self.origin_y_m)

    @property
    def xs_m(self) -> np.ndarray:
        return super().xs_m + self.origin_x_m

    @property
    def ys_m(self) -> np.ndarray:
        return super().ys_m + self.origin_y_m

    def height_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        return super().height_at(np.asarray(x_m) - self.origin_x_m, np.asarray(y_m) - self.origin_y_m)

    def normal_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        return super().normal_at(np.asarray(x_m) - self.origin_x_m, np.asarray(y_m) - self.origin_y_m)

    def material_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        return super().material_at(np.asarray(x_m) - self.origin_x_m, np.asarray(y_m) - self.origin_y_m)

    def height_with_rocks_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        ox, oy = self.origin_x_m, self.origin_y_m
        local = Terrain(self.heights_m, self.cell_size_m, self.materials,
                        [replace(r, x_m=r.x_m - ox, y_m=r.y_m - oy) for r in self.rocks])  # fmt: skip
        return local.height_with_rocks_at(np.asarray(x_m) - ox, np.asarray(y_m) - oy)


class StreamedSite:
    """The tiles of a streamed site (``recipe.streamed``), built on demand, cached (LRU of ``cache_tiles``)."""

    def __init__(self, recipe: TerrainRecipe, seed: int, cache_tiles: int = 64) -> None:
        if recipe.streamed is None:
            raise ValueError("StreamedSite needs a recipe with [terrain.streamed] set")
        self.recipe, self.stream, self.seed = recipe, recipe.streamed, int(seed)
        self.cell_size_m = recipe.cell_size_m
        self.tile_cells = round(self.stream.tile_m / self.cell_size_m)
        self.tile_m = self.tile_cells * self.cell_size_m
        self._cache: OrderedDict[tuple[int, int], TerrainTile] = OrderedDict()
        self._cache_tiles = cache_tiles
        self._albedo: OrderedDict[tuple, np.ndarray] = OrderedDict()
        self.tiles_built = 0
        self._crater_cells: dict[tuple[int, int], list[_Crater]] = {}  # crater cells drawn so far (520 m+ each)
        self._explicit = [_Crater(c.center_xy_m[0], c.center_xy_m[1], c) for c in recipe.craters]
        self.material = {"bedrock": Material.BEDROCK, "mixed": Material.MIXED}.get(recipe.material.kind,
                                                                                   Material.SAND)  # fmt: skip

    # -- relief
    def relief_m(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Ground height (no rocks) at world points: slope + hills + craters + fBm roughness."""
        r, s = self.recipe, self.stream
        x, y = np.broadcast_arrays(np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64))
        az, grade = math.radians(r.slope.azimuth_deg), math.tan(math.radians(r.slope.slope_deg))
        h = r.base_height_m + grade * (math.cos(az) * x + math.sin(az) * y)
        if s.hill_amplitude_m > 0.0:
            h = h + s.hill_amplitude_m * value_noise(x, y, s.hill_wavelength_m, self.seed, LAYER_HILLS)
        h = h + crater_relief_m(x, y, self._craters_near(x, y))
        rough = r.roughness
        if rough.rms_m > 0.0:
            h = h + fbm_world_m(x, y, rough.rms_m, rough.correlation_length_m, rough.octaves, rough.hurst,
                                self.seed, LAYER_ROUGH)  # fmt: skip
        return h

    def _craters_near(self, x: np.ndarray, y: np.ndarray) -> list[_Crater]:
        out = list(self._explicit)
        if self.stream.crater_density_per_km2 > 0.0 and x.size:
            side = 4.0 * self.stream.crater_max_diameter_m
            cx0, cx1 = int(math.floor(x.min() / side)) - 1, int(math.floor(x.max() / side)) + 1
            cy0, cy1 = int(math.floor(y.min() / side)) - 1, int(math.floor(y.max() / side)) + 1
            for cx in range(cx0, cx1 + 1):
                for cy in range(cy0, cy1 + 1):
                    cell = self._crater_cells.get((cx, cy))
                    if cell is None:  # the same draw each time (seeded by the cell): drawn once
                        cell = self._crater_cells[(cx, cy)] = random_craters(self.stream, self.seed, cx, cy)
                    out += cell
        return out

    # -- tiles
    def tile_of(self, x_m: float, y_m: float) -> tuple[int, int]:
        """Index of the tile whose square holds world point (x, y)."""
        return (math.floor(x_m / self.tile_m + 0.5 / self.tile_cells),
                math.floor(y_m / self.tile_m + 0.5 / self.tile_cells))  # fmt: skip

    def tile(self, tx: int, ty: int) -> TerrainTile:
        """Tile ``(tx, ty)``: built from world coordinates and ``(seed, tx, ty)`` only (cached)."""
        key = (tx, ty)
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        t = self._build_tile(tx, ty)
        self._cache[key] = t
        self.tiles_built += 1
        while len(self._cache) > self._cache_tiles:
            self._cache.popitem(last=False)
        return t

    def _build_tile(self, tx: int, ty: int) -> TerrainTile:
        n, c = self.tile_cells, self.cell_size_m
        xs, ys = (tx * n + np.arange(n)) * c, (ty * n + np.arange(n)) * c
        heights = self.relief_m(xs[None, :], ys[:, None])
        return TerrainTile((tx, ty), heights, tuple(self._tile_rocks(tx, ty)))

    def _tile_rocks(self, tx: int, ty: int) -> list[Rock]:
        spec = self.recipe.rocks
        rng = _rng(self.seed, LAYER_ROCKS, tx + _INDEX_OFFSET, ty + _INDEX_OFFSET)
        diam = sample_diameters_m(spec.cover_fraction, spec.min_diameter_m, self.tile_m**2, rng)
        n = len(diam)
        if n == 0:
            return []
        shapes = [s for s in spec.shapes if s in STREAM_ROCK_SHAPES] or list(STREAM_ROCK_SHAPES)
        shape_i = rng.integers(0, len(shapes), n)
        aspect, ratio = rng.uniform(1.0, spec.aspect_ratio_max, n), rng.uniform(*spec.height_to_diameter, n)
        yaw, buried_frac = rng.uniform(0.0, 2.0 * np.pi, n), rng.uniform(*spec.buried_fraction, n)
        xy = (np.array([tx, ty]) - 0.5 / self.tile_cells + rng.uniform(0.0, 1.0, (n, 2))) * self.tile_m
        heights = np.clip(ratio * diam, spec.min_height_m, spec.max_height_m)
        rocks: list[Rock] = []
        placed: list[tuple[float, float, float]] = []
        for k in range(n):
            shape = shapes[shape_i[k]]
            a = 1.0 if shape == "hemispheroid" else float(aspect[k])
            length = float(diam[k]) * math.sqrt(a)
            width = length if shape == "hemispheroid" else float(diam[k]) / math.sqrt(a)
            x, y, rad = float(xy[k, 0]), float(xy[k, 1]), 0.5 * max(length, width)
            if any(math.hypot(x - z.x_m, y - z.y_m) < z.radius_m + rad for z in spec.exclusion_zones):
                continue
            if any(math.hypot(x - px, y - py) < pr + rad for px, py, pr in placed):
                continue
            placed.append((x, y, rad))
            # seat: the base at the lowest ground of the footprint, buried by the drawn fraction plus the relief
            ring = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)
            ground = self.relief_m(np.r_[x, x + rad * np.cos(ring)], np.r_[y, y + rad * np.sin(ring)])
            buried = float(buried_frac[k] / (1.0 - buried_frac[k]) * heights[k]) + float(ground.max() - ground.min())
            rocks.append(Rock(x, y, float(ground[0]), shape, length, width, float(heights[k]), float(yaw[k]),
                              buried, name=f"rock_t{tx}_{ty}_{len(rocks):03d}"))  # type: ignore[arg-type]  # fmt: skip
        return rocks

    def closed_tile(self, tx: int, ty: int) -> WindowTerrain:
        """Tile ``(tx, ty)`` with one more row and column of relief (its east and north edges), as a
        :class:`WindowTerrain`: neighbouring closed tiles share their edges (for meshes of single tiles)."""
        t, n, c = self.tile(tx, ty), self.tile_cells, self.cell_size_m
        xs, ys = (tx * n + np.arange(n + 1)) * c, (ty * n + np.arange(n + 1)) * c
        h = np.empty((n + 1, n + 1))
        h[:n, :n] = t.heights_m
        h[n, :] = self.relief_m(xs, np.full(n + 1, ys[-1]))
        h[:n, n] = self.relief_m(np.full(n, xs[-1]), ys[:n])
        mats = np.full(h.shape, int(self.material), dtype=np.uint8)
        return WindowTerrain(h, c, mats, list(t.rocks), self.seed, self.recipe, 0.5 * (xs[0] + xs[-1]),
                             0.5 * (ys[0] + ys[-1]), (tx, ty))  # fmt: skip

    # -- albedo
    def albedo_tile(
        self, tx: int, ty: int, texels_per_cell: int, contrast: float = 1.0, *, multiscale: bool = False,
        sun_direction: np.ndarray | None = None,
    ) -> np.ndarray:  # fmt: skip
        """Albedo texels of tile ``(tx, ty)``: ``texels_per_cell`` per grid cell a side, texel centres on a world
        lattice (cell ``g`` holds texels at ``(g + (i + 0.5) / texels_per_cell) * cell``), cached like tiles.

        ``multiscale``: the regolith of :func:`terrains.regolith.albedo_tile` (``contrast`` as its ``detail``, its
        micro-relief shaded for ``sun_direction`` if given) on the same lattice; else the classic fBm."""
        sun = None if sun_direction is None else tuple(float(v) for v in np.asarray(sun_direction).ravel())
        key = ("albedo", tx, ty, texels_per_cell, contrast, multiscale, sun)
        if key not in self._albedo:
            m = self.tile_cells * texels_per_cell
            step = self.cell_size_m / texels_per_cell
            if multiscale:
                self._albedo[key] = regolith_tile(tx * m * step, ty * m * step, m, m, 1.0 / step, self.seed,
                                                  detail=contrast, sun_direction=sun_direction)  # fmt: skip
            else:
                xs, ys = (tx * m + np.arange(m) + 0.5) * step, (ty * m + np.arange(m) + 0.5) * step
                self._albedo[key] = albedo_world(xs[None, :], ys[:, None], self.seed, contrast)
            while len(self._albedo) > self._cache_tiles:
                self._albedo.popitem(last=False)
        self._albedo.move_to_end(key)
        return self._albedo[key]

    def window_albedo(
        self, window: WindowTerrain, px_per_m: float, contrast: float = 1.0, *, multiscale: bool = False,
        sun_direction: np.ndarray | None = None,
    ) -> np.ndarray:  # fmt: skip
        """A window's texture (row 0 south, column 0 west) from cached tile texels (:meth:`albedo_tile`): it spans
        exactly the window's grid (the last tile's last cell is left out), so every window agrees texel for texel
        with its neighbours."""
        ppc = max(1, round(px_per_m * self.cell_size_m))
        k = self.stream.window_tiles
        tx0, ty0 = window.window_index[0] - k // 2, window.window_index[1] - k // 2
        kw = {"multiscale": multiscale, "sun_direction": sun_direction}
        rows = [np.hstack([self.albedo_tile(tx0 + a, ty0 + b, ppc, contrast, **kw) for a in range(k)])
                for b in range(k)]  # fmt: skip
        return np.vstack(rows)[:-ppc, :-ppc]

    # -- windows
    def window(self, centre: tuple[int, int]) -> WindowTerrain:
        """The ``window_tiles`` x ``window_tiles`` tiles around ``centre`` as one :class:`WindowTerrain`."""
        k = self.stream.window_tiles
        half = k // 2
        tx0, ty0 = centre[0] - half, centre[1] - half
        rows = [np.hstack([self.tile(tx0 + a, ty0 + b).heights_m for a in range(k)]) for b in range(k)]
        heights = np.vstack(rows)
        rocks = [r for b in range(k) for a in range(k) for r in self.tile(tx0 + a, ty0 + b).rocks]
        n, c = self.tile_cells, self.cell_size_m
        ox = (tx0 * n + 0.5 * (k * n - 1)) * c
        oy = (ty0 * n + 0.5 * (k * n - 1)) * c
        mats = np.full(heights.shape, int(self.material), dtype=np.uint8)
        return WindowTerrain(heights, c, mats, rocks, self.seed, self.recipe, ox, oy, centre)

    @property
    def window_half_m(self) -> float:
        """Half side of a window (metres)."""
        return 0.5 * (self.stream.window_tiles * self.tile_cells - 1) * self.cell_size_m


def window_albedo(window: Terrain, px_per_m: float, seed: int, contrast: float = 1.0) -> np.ndarray:
    """``(H, W)`` albedo texture of a window (``terrains.albedo_texture`` layout: row 0 south, column 0 west),
    sampled from :func:`albedo_world` at texel centres, so neighbouring windows agree texel for texel."""
    width = max(2, round(2.0 * window.half_x_m * px_per_m))
    height = max(2, round(2.0 * window.half_y_m * px_per_m))
    ox, oy = window.origin_xy_m
    x = ox - window.half_x_m + (np.arange(width) + 0.5) * (2.0 * window.half_x_m / width)
    y = oy - window.half_y_m + (np.arange(height) + 0.5) * (2.0 * window.half_y_m / height)
    return albedo_world(x[None, :], y[:, None], seed, contrast)
