"""The orbital products as the localiser holds them: an orthoimage and a DEM on north-aligned grids of the map frame.

Grid convention (as :mod:`terrains`): row ``r`` lies at ``y = y0 + r * px``, column ``c`` at ``x = x0 + c * px``
(pixel centres), so row 0 is the *south* edge; files on disk are north-up (see ``rover_sim.orbital.files``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import map_coordinates


@dataclass(frozen=True)
class Raster:
    """A north-aligned grid: ``values[r, c]`` at ``(x0_m + c px_m, y0_m + r px_m)``; NaN where there is no data."""

    values: np.ndarray
    x0_m: float
    y0_m: float
    px_m: float

    @property
    def shape(self) -> tuple[int, int]:
        return self.values.shape  # type: ignore[return-value]

    def extent_m(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the pixel centres."""
        h, w = self.values.shape
        return self.x0_m, self.x0_m + (w - 1) * self.px_m, self.y0_m, self.y0_m + (h - 1) * self.px_m

    def sample(self, x_m: np.ndarray, y_m: np.ndarray, order: int = 1) -> np.ndarray:
        """Interpolated values at map points (NaN outside the grid)."""
        c = (np.asarray(x_m, float) - self.x0_m) / self.px_m
        r = (np.asarray(y_m, float) - self.y0_m) / self.px_m
        out = map_coordinates(np.nan_to_num(self.values), [r.ravel(), c.ravel()], order=order, mode="nearest")
        h, w = self.values.shape
        inside = (r.ravel() >= 0) & (r.ravel() <= h - 1) & (c.ravel() >= 0) & (c.ravel() <= w - 1)
        return np.where(inside, out, np.nan).reshape(np.shape(x_m))

    def crop(self, x_min: float, x_max: float, y_min: float, y_max: float) -> Raster:
        """The part of the grid within the box (whole pixels; may be empty)."""
        h, w = self.values.shape
        c0 = int(np.clip(np.floor((x_min - self.x0_m) / self.px_m), 0, w))
        c1 = int(np.clip(np.ceil((x_max - self.x0_m) / self.px_m) + 1, 0, w))
        r0 = int(np.clip(np.floor((y_min - self.y0_m) / self.px_m), 0, h))
        r1 = int(np.clip(np.ceil((y_max - self.y0_m) / self.px_m) + 1, 0, h))
        return Raster(self.values[r0:r1, c0:c1], self.x0_m + c0 * self.px_m, self.y0_m + r0 * self.px_m, self.px_m)


@dataclass(frozen=True)
class OrbitalMap:
    """What the orbiter's products tell the rover: the orthoimage (relative radiance), the DEM (metres) and the
    stated error model of the products (from their metadata, never the draw of it).

    ``sun_direction_map`` is the way sunlight travelled when the orthoimage was taken (unit vector, map frame).
    """

    image: Raster
    dem: Raster
    sun_direction_map: np.ndarray
    dem_sigma_m: float
    registration_sigma_m: float
    registration_sigma_rad: float
    psf_sigma_px: float

    def crop(self, centre_xy_m: np.ndarray, half_m: float) -> OrbitalMap:
        """The map within ``half_m`` of ``centre_xy_m`` (a square)."""
        x, y = float(centre_xy_m[0]), float(centre_xy_m[1])
        box = (x - half_m, x + half_m, y - half_m, y + half_m)
        return OrbitalMap(self.image.crop(*box), self.dem.crop(*box), self.sun_direction_map, self.dem_sigma_m,
                          self.registration_sigma_m, self.registration_sigma_rad, self.psf_sigma_px)  # fmt: skip
