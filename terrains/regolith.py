"""Multi-scale regolith albedo as a pure function of world coordinates: fine soil, pebbles, clasts, micro-relief.

The classic sand texture (:mod:`terrains.appearance`) is FFT-filtered noise over the whole site: it cannot be
computed one tile at a time. This one can: every term is a function of the world position ``(x, y)`` and the seed
only (hashed integer lattices, no global state), so adjacent tiles join seamlessly and equal the whole-site texture
(:func:`albedo_tile`, used by the streamed terrain and the moving sun).

Scales (the soil of the MER landing sites: fine dust and sand, a lag of granules and pebbles, scattered clasts;
Golombek et al. 2006, "Geology of the Gusev cratered plains from the Spirit rover traverse", JGR 111 E02S07;
sizes and cover fractions below are approximate, set by eye on rendered navcam views, never tuned on VO results):

* fine soil: value noise at 1.2 cm (grain clusters), 5 cm (ripplets, tracks) and 0.4 m / 2 m (mottling);
* pebbles: one per 4 cm cell with probability 0.22, radius 0.4-1.5 cm, lighter or darker than the soil;
* clasts: one per 20 cm cell with probability 0.12, radius 2-6 cm, mostly darker (dust-coated basalt);
* micro-relief: pebbles and clasts are low domes, the fine soil has ~1 mm relief. With a sun direction the relief
  is baked into the albedo as Lambert shading relative to flat ground (``n.l / l_z``), so the texture's
  appearance depends on the lighting (the renderer re-bakes it when the sun has moved by more than a few degrees;
  rover_sim.world.world). Cast micro-shadows are not modelled.

``detail`` scales every deviation from the mean soil albedo and the relief (Meridiani-like fine soil uses the
appearance module's ``FINE_SOIL_FACTOR``: then pebbles and clasts all but vanish and stereo starves, as it did).
"""

from __future__ import annotations

import numpy as np

SOIL_ALBEDO = 0.58  # as the classic sand (terrains.appearance.SAND_ALBEDO)
# value-noise layers: (lattice spacing m, std of the albedo term)
SOIL_LAYERS = ((0.012, 0.05), (0.05, 0.03), (0.4, 0.03), (2.0, 0.02))
SOIL_RELIEF = ((0.012, 0.0006), (0.05, 0.0012))  # (spacing m, height std m) of the fine soil's relief
# point layers: cell m, probability, radius min/max m, albedo offset min/max, dome height / radius
PEBBLES = (0.04, 0.22, 0.004, 0.015, -0.14, 0.10, 0.6)
CLASTS = (0.20, 0.12, 0.02, 0.06, -0.20, 0.04, 0.5)
EDGE_MARGIN_M = 0.005  # a particle's disc stays this far inside its cell (room for the anti-aliased edge)
SHADE_MAX = 1.8  # a facet facing the sun is at most this much brighter than flat ground
_LAYER_ALBEDO, _LAYER_RELIEF, _LAYER_PEBBLE, _LAYER_CLAST = 100, 200, 300, 400

_M1, _M2, _M3 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xC2B2AE3D27D4EB4F), np.uint64(0x165667B19E3779F9)


def _mix(h: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser (Steele, Lea & Flood 2014): a well-mixed 64-bit hash of ``h``."""
    h = h ^ (h >> np.uint64(30))
    h = h * np.uint64(0xBF58476D1CE4E5B9)
    h = h ^ (h >> np.uint64(27))
    h = h * np.uint64(0x94D049BB133111EB)
    return h ^ (h >> np.uint64(31))


def lattice_uniform(ix: np.ndarray, iy: np.ndarray, seed: int, layer: int) -> np.ndarray:
    """A uniform number in [0, 1) per integer lattice point ``(ix, iy)``, fixed by ``(seed, layer)``."""
    with np.errstate(over="ignore"):
        key = np.uint64((int(seed) * 1000003 + int(layer)) % (1 << 63))
        h = ix.astype(np.int64).astype(np.uint64) * _M1 ^ iy.astype(np.int64).astype(np.uint64) * _M2 ^ key * _M3
        return (_mix(_mix(h)) >> np.uint64(11)).astype(np.float64) * 2.0**-53


def _smoothstep_weights_std() -> float:
    f = (np.arange(100000) + 0.5) / 100000
    u = f * f * (3.0 - 2.0 * f)
    per_axis = float(np.mean((1.0 - u) ** 2 + u**2))
    return float(np.sqrt(1.0 / 3.0) * per_axis)  # corners uniform in [-1, 1]: std 1/sqrt(3)


_VALUE_NOISE_STD = _smoothstep_weights_std()


def value_noise(x_m: np.ndarray, y_m: np.ndarray, spacing_m: float, seed: int, layer: int) -> np.ndarray:
    """Smooth lattice noise, zero mean and about unit std, on the grid ``y_m[:, None], x_m[None, :]`` (1-D)."""
    gx, gy = np.asarray(x_m, dtype=float) / spacing_m, np.asarray(y_m, dtype=float) / spacing_m
    ix, iy = np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)
    fx, fy = gx - ix, gy - iy
    ux, uy = fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy)
    lx, ly = int(ix.min()), int(iy.min())
    table = (
        2.0
        * lattice_uniform(
            np.arange(lx, int(ix.max()) + 2, dtype=np.int64)[None, :],
            np.arange(ly, int(iy.max()) + 2, dtype=np.int64)[:, None],
            seed,
            layer,
        )
        - 1.0
    )  # corner values on the lattice covering the grid (hashed once per lattice point)
    cx, cy = ix - lx, iy - ly
    along_x = table[:, cx] * (1.0 - ux) + table[:, cx + 1] * ux  # (lattice rows, nx)
    out = along_x[cy] * (1.0 - uy)[:, None] + along_x[cy + 1] * uy[:, None]
    return out / _VALUE_NOISE_STD


def _points(
    x_m: np.ndarray, y_m: np.ndarray, px_m: float, params: tuple, seed: int, layer: int
) -> tuple[np.ndarray, np.ndarray]:
    """Albedo offset and dome height of one scattered-particle layer on the grid ``y_m[:, None], x_m[None, :]``.

    At most one particle per cell, kept inside its cell (``EDGE_MARGIN_M`` clear of the border), so each pixel
    looks up its own cell only.
    """
    cell, prob, r_min, r_max, a_min, a_max, dome = params
    ci_x, ci_y = np.floor(x_m / cell).astype(np.int64), np.floor(y_m / cell).astype(np.int64)
    lo_x, lo_y = int(ci_x.min()), int(ci_y.min())
    gx = np.arange(lo_x, int(ci_x.max()) + 1, dtype=np.int64)[None, :]
    gy = np.arange(lo_y, int(ci_y.max()) + 1, dtype=np.int64)[:, None]
    attr = [lattice_uniform(gx, gy, seed, layer + k) for k in range(5)]  # presence, cx, cy, radius, albedo
    radius = np.where(attr[0] < prob, r_min + attr[3] * (r_max - r_min), 0.0)
    margin = radius + EDGE_MARGIN_M
    cx = (gx * cell + margin + attr[1] * (cell - 2.0 * margin))[:, ci_x - lo_x]  # (cell rows, nx)
    cy = (gy * cell + margin + attr[2] * (cell - 2.0 * margin))[ci_y - lo_y]  # (ny, cell cols)
    rows, cols = (ci_y - lo_y)[:, None], (ci_x - lo_x)[None, :]
    r = radius[rows, cols]
    d = np.hypot(x_m[None, :] - cx[ci_y - lo_y], y_m[:, None] - cy[:, ci_x - lo_x])
    cover = np.clip((r - d) / px_m + 0.5, 0.0, 1.0)  # anti-aliased disc edge, one pixel wide
    albedo = cover * (a_min + attr[4] * (a_max - a_min))[rows, cols]
    height = dome * np.sqrt(np.clip(r * r - d * d, 0.0, None))
    return albedo, height


def regolith_fields(
    x_m: np.ndarray, y_m: np.ndarray, seed: int, detail: float | np.ndarray = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """(albedo, height m) of the regolith on the grid ``y_m[:, None], x_m[None, :]`` (1-D, evenly spaced)."""
    px_m = float(abs(x_m[1] - x_m[0])) if x_m.size > 1 else 0.01
    dev = sum(std * value_noise(x_m, y_m, s, seed, _LAYER_ALBEDO + k) for k, (s, std) in enumerate(SOIL_LAYERS))
    relief = sum(std * value_noise(x_m, y_m, s, seed, _LAYER_RELIEF + k) for k, (s, std) in enumerate(SOIL_RELIEF))
    peb_a, peb_h = _points(x_m, y_m, px_m, PEBBLES, seed, _LAYER_PEBBLE)
    cla_a, cla_h = _points(x_m, y_m, px_m, CLASTS, seed, _LAYER_CLAST)
    albedo = SOIL_ALBEDO + detail * (dev + peb_a + cla_a)
    height = detail * (relief + np.maximum(peb_h, cla_h))
    return albedo, height


def relief_shading(height_m: np.ndarray, px_m: float, to_sun: np.ndarray) -> np.ndarray:
    """Lambert shading of a height grid with a one-pixel halo, relative to flat ground; halo dropped."""
    hy, hx = np.gradient(height_m, px_m)
    hx, hy = hx[1:-1, 1:-1], hy[1:-1, 1:-1]
    lx, ly, lz = (float(v) for v in to_sun)
    lz = max(lz, 0.05)
    n_dot_l = (-hx * lx - hy * ly + lz) / np.sqrt(1.0 + hx * hx + hy * hy)
    return np.clip(n_dot_l / lz, 0.0, SHADE_MAX)


def regolith_albedo(
    x_m: np.ndarray,
    y_m: np.ndarray,
    seed: int,
    *,
    detail: float | np.ndarray = 1.0,
    sun_direction: np.ndarray | None = None,
) -> np.ndarray:
    """Regolith albedo on the grid ``y_m[:, None], x_m[None, :]``, lit by ``sun_direction`` if given (unshaded
    otherwise); ``sun_direction`` is the way sunlight travels (site frame, as ``Sun.direction()``)."""
    if sun_direction is None:
        return regolith_fields(x_m, y_m, seed, detail)[0]
    step_x = float(x_m[1] - x_m[0]) if x_m.size > 1 else 0.01
    step_y = float(y_m[1] - y_m[0]) if y_m.size > 1 else step_x
    xh = np.concatenate([[x_m[0] - step_x], x_m, [x_m[-1] + step_x]])
    yh = np.concatenate([[y_m[0] - step_y], y_m, [y_m[-1] + step_y]])
    det = np.pad(detail, 1, mode="edge") if np.ndim(detail) == 2 else detail
    albedo, height = regolith_fields(xh, yh, seed, det)
    shade = relief_shading(height, abs(step_x), -np.asarray(sun_direction, dtype=float))
    return albedo[1:-1, 1:-1] * shade


def albedo_tile(
    x0_m: float,
    y0_m: float,
    nx: int,
    ny: int,
    px_per_m: float,
    seed: int,
    *,
    detail: float = 1.0,
    sun_direction: np.ndarray | None = None,
) -> np.ndarray:
    """Regolith albedo of the tile whose south-west corner is ``(x0_m, y0_m)``: ``(ny, nx)`` float32 in [0, 1].

    Pixel ``[r, c]`` is centred at ``(x0 + (c + 0.5) / px_per_m, y0 + (r + 0.5) / px_per_m)`` (row = north, as
    :func:`terrains.albedo_texture`). Adjacent tiles on the same pixel grid join seamlessly and equal one tile
    covering both (up to float rounding): every term is a function of world position and seed only.
    """
    if not (px_per_m > 0.0 and np.isfinite(px_per_m)) or nx < 2 or ny < 2:
        raise ValueError(f"albedo_tile needs px_per_m > 0 and nx, ny >= 2, got {px_per_m}, {nx}, {ny}")
    x = x0_m + (np.arange(nx) + 0.5) / px_per_m
    y = y0_m + (np.arange(ny) + 0.5) / px_per_m
    out = regolith_albedo(x, y, seed, detail=detail, sun_direction=sun_direction)
    return np.clip(out, 0.0, 1.0).astype(np.float32)
