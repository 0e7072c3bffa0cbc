"""Make the orbital products of a scenario's site: a nadir orthoimage and a DEM in the (slightly wrong) map frame.

The image is computed from the terrain in numpy, not rendered through MuJoCo: a nadir view at 0.25 m/pixel needs
no perspective, occlusion or shadow-map machinery, and numpy makes it deterministic, independent of GL and of the
renderer's window (streamed sites have no whole-site render model), and cheap to make tile by tile. The radiance
uses the simulator's own photometry (``rover_sim.render.renderer``: a sky term plus a Lambertian sun, the ground's
albedo times the Mars tint, rocks' albedo times the rock tint, as Rec. 601 luminance):

1. on a fine grid (``FINE_PER_PX`` samples per image pixel, the true site frame): ground and rock heights, albedo,
   Lambert shading of the relief and rocks for the orbiter's sun, cast shadows by marching toward the sun;
2. the map frame's grid mapped through the registration error (one seeded offset and rotation of the whole map)
   into the site frame and the radiance resampled there; each image pixel integrates its fine samples (area mean);
3. the optics' blur (Gaussian PSF), shot-noise-like noise at the stated SNR, 14-bit counts;
4. the DEM: the mean height (rocks included) of each post, plus spatially correlated error of the stated sigma.

The error model and its sources: :mod:`rover_sim.orbital.spec`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter, map_coordinates, shift
from scipy.spatial import cKDTree

from nav.globalloc.maps import OrbitalMap, Raster
from rover_sim.orbital.spec import OrbitalSpec
from rover_sim.render.config import RenderConfig
from rover_sim.render.render_world import ROCK_TINT_RGB
from rover_sim.render.renderer import LUMA_WEIGHTS
from rover_sim.sim.assembly import Sun
from rover_sim.sim.ephemeris import sun_azimuth_elevation_deg
from terrains import Terrain, albedo_texture, rock_albedo, synthesize
from terrains.appearance import MARS_TINT_RGB
from terrains.regolith import regolith_albedo
from terrains.stream import StreamedSite, WindowTerrain, albedo_world
from terrains.terrain import Material

FINE_PER_PX = 5  # fine samples per image pixel a side (0.05 m at 0.25 m/pixel)
DN_MEAN = 4000.0  # counts of the mean signal (14-bit range 0-16383)
SHADOW_MAX_HEIGHT_M = 2.0  # cast shadows are marched far enough for an obstacle this tall
GROUND_LUMA = float(LUMA_WEIGHTS @ np.asarray(MARS_TINT_RGB, dtype=np.float32))
ROCK_LUMA = float(LUMA_WEIGHTS @ np.asarray(ROCK_TINT_RGB, dtype=np.float32))
_RNG_KEY = 0x0B17A1  # the orbital products' random stream (registration, noise, DEM error), beside the scenario seed


@dataclass(frozen=True)
class Registration:
    """The map frame's error: a site-frame point ``p = R(theta) p_map + t`` is what the map shows at ``p_map``."""

    offset_xy_m: tuple[float, float]
    rotation_rad: float

    @classmethod
    def draw(cls, spec: OrbitalSpec, seed: int) -> Registration:
        rng = np.random.default_rng([int(seed), _RNG_KEY, 1])
        t = rng.normal(0.0, spec.registration_sigma_m, 2)
        th = rng.normal(0.0, math.radians(spec.registration_sigma_deg))
        return cls((float(t[0]), float(t[1])), float(th))

    def to_site(self, x_m: np.ndarray, y_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c, s = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        return c * x_m - s * y_m + self.offset_xy_m[0], s * x_m + c * y_m + self.offset_xy_m[1]


@dataclass(frozen=True)
class Box:
    """A map-frame rectangle of pixel centres (x0, y0 the south-west pixel centre)."""

    x0_m: float
    y0_m: float
    width_m: float
    height_m: float


def orbital_sun_direction(latitude_deg: float, solar_longitude_deg: float, local_solar_time_h: float) -> np.ndarray:
    """The way sunlight travels (site frame) at the orbiter's local time."""
    az, el = sun_azimuth_elevation_deg(latitude_deg, solar_longitude_deg, local_solar_time_h)
    return Sun(az, max(el, 5.0)).direction()


class SiteSampler:
    """Heights, rock heights and albedo of a site on fine grids of the site frame (a whole site or a streamed one)."""

    def __init__(self, scenario: object) -> None:
        sc = scenario
        self.seed, self.ap = int(sc.seed), sc.appearance  # type: ignore[attr-defined]
        recipe = sc.terrain  # type: ignore[attr-defined]
        self.streamed = StreamedSite(recipe, self.seed) if recipe.streamed is not None else None
        self.terrain: Terrain | None = None
        self.albedo_grid: Raster | None = None
        if self.streamed is None:
            self.terrain = synthesize(recipe, self.seed)
            t = self.terrain
            self_fine_m = 0.05
            px_per_m = 1.0 / self_fine_m
            a = albedo_texture(t, px_per_m, self.seed, fine_soil=self.ap.fine_soil, contrast=self.ap.contrast,
                               patches=self.ap.patch_tuples(), regolith=self.ap.regolith)  # fmt: skip
            h, w = a.shape
            self.albedo_grid = Raster(a, -t.half_x_m + 0.5 * 2 * t.half_x_m / w, -t.half_y_m + 0.5 * 2 * t.half_y_m / h,
                                      self_fine_m)  # fmt: skip

    def fields(self, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(ground height, height with rocks, luminance albedo) on the grid ``ys[:, None], xs[None, :]``."""
        X, Y = np.meshgrid(xs, ys)
        if self.terrain is not None:
            t = self.terrain
            ground = t.height_at(X, Y)
            top = t.height_with_rocks_at(X, Y)
            assert self.albedo_grid is not None
            albedo = self.albedo_grid.sample(X, Y)
            albedo = np.where(np.isnan(albedo), float(np.nanmean(self.albedo_grid.values)), albedo)
            rocks = t.rocks
        else:
            s = self.streamed
            assert s is not None
            ground = s.relief_m(X, Y)
            tx0, ty0 = s.tile_of(float(xs[0]), float(ys[0]))
            tx1, ty1 = s.tile_of(float(xs[-1]), float(ys[-1]))
            tiles = [(tx, ty) for tx in range(tx0 - 1, tx1 + 2) for ty in range(ty0 - 1, ty1 + 2)]
            rocks = [r for tx, ty in tiles for r in s.tile(tx, ty).rocks]
            step = float(xs[1] - xs[0])
            mats = np.full(ground.shape, int(Material.SAND), dtype=np.uint8)
            ox, oy = 0.5 * (xs[0] + xs[-1]), 0.5 * (ys[0] + ys[-1])
            win = WindowTerrain(ground, step, mats, rocks, self.seed, s.recipe, ox, oy, (0, 0))
            top = np.maximum(win.height_with_rocks_at(X, Y), ground)
            if self.ap.regolith == "multiscale":
                albedo = regolith_albedo(xs, ys, self.seed, detail=self.ap.contrast)
            else:
                albedo = albedo_world(xs[None, :], ys[:, None], self.seed, self.ap.contrast)
        luma = albedo * GROUND_LUMA
        on_rock = top > ground + 0.005
        if rocks and on_rock.any():
            tree = cKDTree(np.array([[r.x_m, r.y_m] for r in rocks]))
            _, idx = tree.query(np.c_[X[on_rock], Y[on_rock]])
            grey = np.array([rock_albedo(r, self.seed) for r in rocks])
            luma[on_rock] = grey[idx] * ROCK_LUMA
        return ground, top, luma


def shade_and_shadow(top_m: np.ndarray, step_m: float, sun_direction: np.ndarray, cfg: RenderConfig) -> np.ndarray:
    """Relative irradiance of each sample: sky + sun * max(n.l, 0) * lit (the renderer's lighting model), lit from
    a march of the height grid toward the sun (cast shadows of rocks and relief)."""
    to_sun = -np.asarray(sun_direction, dtype=float)
    gy, gx = np.gradient(top_m, step_m)
    cos_i = (-gx * to_sun[0] - gy * to_sun[1] + to_sun[2]) / np.sqrt(1.0 + gx * gx + gy * gy)
    horiz = math.hypot(to_sun[0], to_sun[1])
    lit = np.ones(top_m.shape, dtype=bool)
    if horiz > 1e-6:
        ux, uy, tan_el = to_sun[0] / horiz, to_sun[1] / horiz, to_sun[2] / horiz
        n_steps = int(math.ceil(SHADOW_MAX_HEIGHT_M / max(tan_el, 0.05) / step_m))
        for k in range(1, n_steps + 1):
            # the height k steps toward the sun, at every sample (shift moves content: sample at +k u)
            ahead = shift(top_m, (-k * uy, -k * ux), order=1, mode="nearest")
            lit &= ahead <= top_m + k * step_m * tan_el + 1e-3
    return cfg.sky_ambient + cfg.sun_intensity * np.clip(cos_i, 0.0, None) * lit


def make_products(scenario: object, box: Box, spec: OrbitalSpec | None = None) -> tuple[OrbitalMap, Registration]:
    """The orthoimage and DEM of ``box`` (map frame) of ``scenario``'s site, and the registration error drawn."""
    sc = scenario
    spec = spec or sc.orbital  # type: ignore[attr-defined]
    seed = int(sc.seed)  # type: ignore[attr-defined]
    reg = Registration.draw(spec, seed)
    sun = orbital_sun_direction(sc.sun.latitude_deg, sc.sun.solar_longitude_deg, spec.local_solar_time_h)  # type: ignore[attr-defined]
    px, fine = spec.image_px_m, spec.image_px_m / FINE_PER_PX
    # map-frame image grid, rounded to whole DEM posts
    k_dem = max(1, round(spec.dem_px_m / px))
    nx = int(math.ceil(box.width_m / (px * k_dem))) * k_dem
    ny = int(math.ceil(box.height_m / (px * k_dem))) * k_dem
    # fine map-frame sample centres of each image pixel, mapped into the site frame
    fx = box.x0_m - 0.5 * px + (np.arange(nx * FINE_PER_PX) + 0.5) * fine
    fy = box.y0_m - 0.5 * px + (np.arange(ny * FINE_PER_PX) + 0.5) * fine
    MX, MY = np.meshgrid(fx, fy)
    SX, SY = reg.to_site(MX, MY)
    # site-frame fine grid covering them
    margin = 4 * fine
    xs = np.arange(SX.min() - margin, SX.max() + margin + fine, fine)
    ys = np.arange(SY.min() - margin, SY.max() + margin + fine, fine)
    sampler = SiteSampler(sc)
    _ground, top, luma = sampler.fields(xs, ys)
    radiance = luma * shade_and_shadow(top, fine, sun, RenderConfig())
    coords = [(SY - ys[0]) / fine, (SX - xs[0]) / fine]
    rad_map = map_coordinates(radiance, coords, order=1, mode="nearest")
    top_map = map_coordinates(top, coords, order=1, mode="nearest")
    image = rad_map.reshape(ny, FINE_PER_PX, nx, FINE_PER_PX).mean(axis=(1, 3))
    rng = np.random.default_rng([seed, _RNG_KEY, 2])
    if spec.psf_sigma_px > 0:
        image = gaussian_filter(image, spec.psf_sigma_px, mode="nearest")
    mean = float(image.mean())
    image = image + rng.normal(0.0, 1.0, image.shape) * (mean / spec.snr) * np.sqrt(np.clip(image / mean, 0.0, None))
    dn = np.clip(np.rint(image * (DN_MEAN / mean)), 0, 16383).astype(np.float32)
    kf = FINE_PER_PX * k_dem
    dem = top_map.reshape(ny // k_dem, kf, nx // k_dem, kf).mean(axis=(1, 3))
    dem = dem + correlated_noise(dem.shape, spec.dem_px_m, spec.dem_sigma_m, spec.dem_error_correlation_m, rng)
    dem_px = px * k_dem
    image_r = Raster(dn, box.x0_m, box.y0_m, px)
    dem_r = Raster(dem.astype(np.float32), box.x0_m - 0.5 * px + 0.5 * dem_px, box.y0_m - 0.5 * px + 0.5 * dem_px,
                   dem_px)  # fmt: skip
    omap = OrbitalMap(image_r, dem_r, sun, spec.dem_sigma_m, spec.registration_sigma_m,
                      math.radians(spec.registration_sigma_deg), spec.psf_sigma_px)  # fmt: skip
    return omap, reg


def correlated_noise(shape: tuple[int, int], px_m: float, sigma_m: float, corr_m: float,
                     rng: np.random.Generator) -> np.ndarray:  # fmt: skip
    """Gaussian noise of std ``sigma_m`` smoothed over ``corr_m`` (a Gaussian kernel of sigma corr/2)."""
    white = rng.normal(0.0, 1.0, shape)
    if corr_m > 0:
        white = gaussian_filter(white, 0.5 * corr_m / px_m, mode="wrap")
        white /= max(float(white.std()), 1e-12)
    return sigma_m * white


def site_boxes(scenario: object, spec: OrbitalSpec | None = None) -> list[Box]:
    """The product boxes of a site: the whole patch, or for a streamed site the tiles of ``spec.tile_m`` within
    ``spec.route_margin_m`` of the route (the start and every waypoint of the commands, joined in order)."""
    sc = scenario
    spec = spec or sc.orbital  # type: ignore[attr-defined]
    px = spec.image_px_m
    recipe = sc.terrain  # type: ignore[attr-defined]
    if recipe.streamed is None:
        nrow, ncol = recipe.grid_shape
        hx, hy = (ncol - 1) * recipe.cell_size_m / 2, (nrow - 1) * recipe.cell_size_m / 2
        return [Box(-hx + 0.5 * px, -hy + 0.5 * px, 2 * hx - px, 2 * hy - px)]
    pts = [(sc.start.x_m, sc.start.y_m)]  # type: ignore[attr-defined]
    for cmd in sc.commands:  # type: ignore[attr-defined]
        if hasattr(cmd, "x_m") and hasattr(cmd, "y_m"):
            pts.append((float(cmd.x_m), float(cmd.y_m)))
    route = np.array(pts, dtype=float)
    T = spec.tile_m
    lo = np.floor((route.min(axis=0) - spec.route_margin_m) / T).astype(int)
    hi = np.floor((route.max(axis=0) + spec.route_margin_m) / T).astype(int)
    boxes = []
    for i in range(lo[0], hi[0] + 1):
        for j in range(lo[1], hi[1] + 1):
            centre = np.array([(i + 0.5) * T, (j + 0.5) * T])
            if route_distance_m(route, centre) <= spec.route_margin_m + T / math.sqrt(2):
                boxes.append(Box(i * T + 0.5 * px, j * T + 0.5 * px, T - px, T - px))
    return boxes


def route_distance_m(route: np.ndarray, p: np.ndarray) -> float:
    """Distance from ``p`` to the polyline ``route`` (N, 2)."""
    if len(route) == 1:
        return float(np.linalg.norm(p - route[0]))
    a, b = route[:-1], route[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0.0, 1.0)
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1)))
