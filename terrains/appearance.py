"""Procedural albedo (surface brightness) for rendering a terrain: the texture the navigation cameras see.

Stereo and visual odometry live or die by surface texture, so the contrast is a parameter: ``fine_soil=True``
makes the sand nearly featureless, as on the Meridiani plains where hazcam stereo and VO starved for texture
(Maimone et al., "Autonomous Navigation Results from the MER Mission"). Values are relative albedo in
``[0, 1]`` for the renderer, not calibrated Lambert albedo; the butterscotch colour comes from
:func:`texture_rgb_u8`.

Texture layout: ``albedo[r, c]`` covers the patch with ``H x W`` square-ish pixels; row ``r`` increases with y
(north) and column ``c`` with x (east), like the heightfield rows and columns. Pixel centres are at
``x = -half_x + (c + 0.5) * 2 half_x / W`` and ``y = -half_y + (r + 0.5) * 2 half_y / H``. (An image file
viewer shows row 0 at the top, so flip rows for a north-up picture.)
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable
from enum import IntEnum

import numpy as np

from terrains._noise import layer_rng, smooth_noise
from terrains.regolith import regolith_albedo
from terrains.terrain import Material, Rock, Terrain, bilinear_sample

MARS_TINT_RGB = (0.76, 0.55, 0.40)  # butterscotch dust colour, multiplies the albedo

# Mean relative albedo per material: bright dusty sand, darker basaltic/sulfate outcrop.
SAND_ALBEDO = 0.58
BEDROCK_ALBEDO = 0.46
# Sand detail: per-pixel grain speckle and metre-scale mottling (std of each term at contrast 1).
SAND_SPECKLE = 0.06
SAND_MOTTLE = 0.035
FINE_SOIL_FACTOR = 0.06  # fine_soil multiplies the sand detail by this (Meridiani-like, starves stereo)
SAND_MOTTLE_SCALE_M = 0.4
PATCH_EDGE_M = 0.1  # a coarse-soil patch blends into the fine soil over this width
# Bedrock: layered banding (layers about 4 cm thick, as in Burns formation outcrop), fine laminae, cracks.
LAYER_THICKNESS_M = 0.04
LAYER_CONTRAST = 0.07
LAMINA_CONTRAST = 0.02
BEDROCK_SPECKLE = 0.04
LAYER_WARP_SCALE_M = 1.5  # bedding planes bend on this scale ...
LAYER_WARP_M = 0.25  # ... by about this much
CRACK_SCALE_M = 0.5  # spacing of the polygonal crack network
CRACK_SHARPNESS = 0.05  # crack line half-width in units of the crack field's std
CRACK_DARKENING = 0.25
# Mixed ground (thin sand over rock, gravel): the mean of sand and rock, the sand's detail damped, the rock's
# layering showing through, plus sparse pebbles; its contrast lies between the two.
MIXED_SAND_DETAIL = 0.5
MIXED_ROCK_DETAIL = 0.7
PEBBLE_THRESHOLD = 2.2  # std units of the pebble field above which a pixel is a pebble
PEBBLE_CONTRAST = 0.12
# Drift (loose, fine, dust-rich: the Purgatory ripple): a little brighter than the plains' sand and smoother (its
# grain-scale detail damped; the ripples' own relief still shades it).
DRIFT_ALBEDO_OFFSET = 0.04
DRIFT_SAND_DETAIL = 0.4


class _Part(IntEnum):
    """Stable identifiers of the random texture components (generator spawn keys). Never renumber."""

    SAND_SPECKLE = 11
    SAND_MOTTLE = 12
    LAYER_ANGLE = 21
    LAYER_TABLE = 22
    LAYER_WARP = 23
    CRACKS = 24
    BEDROCK_SPECKLE = 25
    PEBBLES = 31


def albedo_texture(
    terrain: Terrain,
    px_per_m: float,
    seed: int,
    *,
    fine_soil: bool = False,
    contrast: float = 1.0,
    patches: tuple[tuple[float, float, float, float], ...] = (),
    regolith: str = "classic",
    sun_direction: np.ndarray | None = None,
) -> np.ndarray:
    """Relative albedo of the ground, ``(H, W)`` float32 in ``[0, 1]``, blended across materials.

    Sand: fine low-contrast speckle plus mottling (nearly featureless with ``fine_soil``). Bedrock: layered
    banding with higher contrast, plus dark cracks. Mixed: between the two, with pebbles. ``contrast`` scales
    every deviation from the mean albedo of each material. ``patches``: discs ``(x_m, y_m, radius_m, detail)``
    of coarser soil inside fine soil, where the sand's detail is ``detail`` times the ordinary sand's (1.0:
    ordinary soil texture) instead of ``FINE_SOIL_FACTOR``; the edge blends over ``PATCH_EDGE_M``. Deterministic
    in ``(terrain, px_per_m, seed, options)``. ``regolith="multiscale"``: the sand is the world-coordinate
    multi-scale regolith of :mod:`terrains.regolith` (fine soil, pebbles, clasts; its relief shaded for
    ``sun_direction`` when given) instead of the classic FFT speckle.
    """
    if regolith not in ("classic", "multiscale"):
        raise ValueError(f"regolith must be 'classic' or 'multiscale', got {regolith!r}")
    if not (px_per_m > 0.0 and math.isfinite(px_per_m)):
        raise ValueError(f"px_per_m must be a positive number, got {px_per_m}")
    if contrast < 0.0:
        raise ValueError(f"contrast must be >= 0, got {contrast}")
    width = max(2, round(2.0 * terrain.half_x_m * px_per_m))
    height = max(2, round(2.0 * terrain.half_y_m * px_per_m))
    x = -terrain.half_x_m + (np.arange(width) + 0.5) * (2.0 * terrain.half_x_m / width)
    y = -terrain.half_y_m + (np.arange(height) + 0.5) * (2.0 * terrain.half_y_m / height)
    fields = _MaterialFields((height, width), x, y, px_per_m, seed, fine_soil, contrast, patches)
    if regolith == "multiscale":
        fields.multiscale, fields.sun_direction = True, sun_direction

    present = [Material(m) for m in np.unique(terrain.materials)]
    if len(present) == 1:
        out = fields.of(present[0])
    else:
        out = np.zeros((height, width), dtype=np.float32)
        for m in present:
            one_hot = (terrain.materials == m).astype(np.float32)
            weight = bilinear_sample(one_hot, terrain.cell_size_m, x[None, :], y[:, None])
            out += weight * fields.of(m)
    return np.clip(out, 0.0, 1.0).astype(np.float32, copy=False)


class _MaterialFields:
    """Lazily built albedo fields of each material over one pixel grid (each built at most once)."""

    def __init__(
        self,
        shape: tuple[int, int],
        x_m: np.ndarray,
        y_m: np.ndarray,
        px_per_m: float,
        seed: int,
        fine_soil: bool,
        contrast: float,
        patches: tuple[tuple[float, float, float, float], ...] = (),
    ) -> None:
        self.shape, self.x, self.y, self.ppm, self.seed = shape, x_m, y_m, px_per_m, seed
        self.fine_soil, self.contrast, self.patches = fine_soil, contrast, patches
        self._cache: dict[Material, np.ndarray] = {}
        self.multiscale, self.sun_direction = False, None

    def of(self, material: Material) -> np.ndarray:
        builders: dict[Material, Callable[[], np.ndarray]] = {
            Material.SAND: self._sand,
            Material.BEDROCK: self._bedrock,
            Material.MIXED: self._mixed,
            Material.DRIFT: self._drift,
        }
        if material not in self._cache:
            self._cache[material] = builders[material]().astype(np.float32)
        return self._cache[material]

    def _noise(self, part: _Part, sigma_px: float) -> np.ndarray:
        return smooth_noise(self.shape, sigma_px, layer_rng(self.seed, part))

    def _sand_detail(self) -> float | np.ndarray:
        """Sand detail factor per pixel: fine soil with coarser patches (see :func:`albedo_texture`)."""
        if not self.fine_soil:
            return 1.0
        out: float | np.ndarray = FINE_SOIL_FACTOR
        for px, py, radius, detail in self.patches:
            r = np.hypot(self.x[None, :] - px, self.y[:, None] - py)
            w = np.clip((radius - r) / PATCH_EDGE_M + 0.5, 0.0, 1.0)
            out = np.maximum(out, FINE_SOIL_FACTOR + w * (detail - FINE_SOIL_FACTOR))
        return out

    def _sand(self) -> np.ndarray:
        detail = self.contrast * self._sand_detail()
        if self.multiscale:
            return regolith_albedo(self.x, self.y, self.seed, detail=detail, sun_direction=self.sun_direction)
        speckle = self._noise(_Part.SAND_SPECKLE, 0.6)
        mottle = self._noise(_Part.SAND_MOTTLE, SAND_MOTTLE_SCALE_M * self.ppm)
        return SAND_ALBEDO + detail * (SAND_SPECKLE * speckle + SAND_MOTTLE * mottle)

    def _bedrock(self) -> np.ndarray:
        strike = layer_rng(self.seed, _Part.LAYER_ANGLE).uniform(0.0, np.pi)
        warp = LAYER_WARP_M * self._noise(_Part.LAYER_WARP, LAYER_WARP_SCALE_M * self.ppm)
        across = math.cos(strike) * self.x[None, :] + math.sin(strike) * self.y[:, None] + warp
        table = layer_rng(self.seed, _Part.LAYER_TABLE).standard_normal(4096)
        layer = table[np.floor(across / LAYER_THICKNESS_M).astype(np.int64) % table.size]
        lamina = np.sin(2.0 * np.pi * 4.0 * across / LAYER_THICKNESS_M)
        cracks = np.exp(-((self._noise(_Part.CRACKS, CRACK_SCALE_M * self.ppm) / CRACK_SHARPNESS) ** 2))
        speckle = self._noise(_Part.BEDROCK_SPECKLE, 0.8)
        deviation = LAYER_CONTRAST * layer + LAMINA_CONTRAST * lamina + BEDROCK_SPECKLE * speckle
        return BEDROCK_ALBEDO + self.contrast * (deviation - CRACK_DARKENING * cracks)

    def _mixed(self) -> np.ndarray:
        pebbles = self._noise(_Part.PEBBLES, 1.0)
        pebble = np.where(np.abs(pebbles) > PEBBLE_THRESHOLD, np.sign(pebbles) * PEBBLE_CONTRAST, 0.0)
        sand, rock = self.of(Material.SAND), self.of(Material.BEDROCK)
        mean = 0.5 * (SAND_ALBEDO + BEDROCK_ALBEDO)
        detail = MIXED_SAND_DETAIL * (sand - SAND_ALBEDO) + MIXED_ROCK_DETAIL * (rock - BEDROCK_ALBEDO)
        return mean + detail + self.contrast * pebble


    def _drift(self) -> np.ndarray:
        sand = self.of(Material.SAND)
        return SAND_ALBEDO + DRIFT_ALBEDO_OFFSET + DRIFT_SAND_DETAIL * (sand - SAND_ALBEDO)


def rock_albedo(rock: Rock, seed: int) -> float:
    """Base grey level of a rock in ``[0.25, 0.6]``: dark basalt to dust-coated, fixed per rock and seed."""
    key = zlib.crc32(repr((rock.name, round(rock.x_m, 6), round(rock.y_m, 6))).encode())
    return float(np.random.default_rng([int(seed), key]).uniform(0.25, 0.6))


def texture_rgb_u8(albedo: np.ndarray, tint: tuple[float, float, float] = MARS_TINT_RGB) -> np.ndarray:
    """``(H, W, 3)`` uint8 image: albedo times a tint (default Mars butterscotch), for MuJoCo textures."""
    rgb = np.clip(np.asarray(albedo, dtype=np.float32)[..., None] * np.asarray(tint, dtype=np.float32), 0.0, 1.0)
    return np.rint(rgb * 255.0).astype(np.uint8)
