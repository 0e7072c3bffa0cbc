"""Orbital products on disk: north-up rasters with world files and a JSON metadata file.

Format: the orthoimage as a 16-bit greyscale PNG (``ortho*.png`` + ``.pgw`` world file: 14-bit counts as HiRISE
returns them), the DEM as a single-band float32 TIFF (``dem*.tif`` + ``.tfw``: metres, no scaling to undo), and
``orbital.json`` (the frame, the sun, the error model with its sources, the files). Why not GeoTIFF: writing GeoTIFF
tags needs GDAL (rasterio) or a TIFF library the simulator does not otherwise depend on, while PNG and TIFF with
world files are written with OpenCV (already a dependency) and read by every GIS and by GDAL/rasterio with the
right georeference (the world file gives the pixel size and the centre of the upper-left pixel); the site frame is
a local engineering frame (x east, y north, metres) with no EPSG code, which GeoTIFF could not name either.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import cv2
import numpy as np

from nav.globalloc.maps import OrbitalMap, Raster
from rover_sim.errors import ConfigError

METADATA = "orbital.json"
FORMAT = "rover-sim-orbital"
VERSION = 1


def world_file_lines(r: Raster) -> list[str]:
    """The six lines of an ESRI world file for a north-up raster (centre of the upper-left = north-west pixel)."""
    h, _w = r.shape
    return [f"{r.px_m!r}", "0.0", "0.0", f"{-r.px_m!r}", f"{r.x0_m!r}", f"{r.y0_m + (h - 1) * r.px_m!r}"]


def write_raster(path: Path, r: Raster, dtype: type) -> None:
    north_up = np.ascontiguousarray(np.flipud(r.values)).astype(dtype)
    if not cv2.imwrite(str(path), north_up):
        raise OSError(f"could not write {path}")
    suffix = {".png": ".pgw", ".tif": ".tfw"}[path.suffix]
    path.with_suffix(suffix).write_text("\n".join(world_file_lines(r)) + "\n")


def read_raster(path: Path) -> Raster:
    """A raster written by :func:`write_raster` (any north-up raster with a world file)."""
    values = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if values is None:
        raise ConfigError(str(path), "(file)", "cannot read the raster (missing or not an image)")
    wf = path.with_suffix({".png": ".pgw", ".tif": ".tfw"}[path.suffix])
    try:
        a, d, b, e, c, f = (float(v) for v in wf.read_text().split())
    except (OSError, ValueError):
        raise ConfigError(str(wf), "(file)", "missing or malformed world file (six numbers)") from None
    if d != 0.0 or b != 0.0 or abs(a + e) > 1e-9 * abs(a) or a <= 0:
        raise ConfigError(str(wf), "(file)", "only north-up rasters with square pixels are supported")
    h = values.shape[0]
    return Raster(np.flipud(values).astype(np.float32), c, f - (h - 1) * a, a)


def write_products(out_dir: Path, tiles: list[tuple[str, OrbitalMap]], metadata: dict) -> list[Path]:
    """Write each tile's orthoimage and DEM (suffix ``name``) and ``orbital.json``; returns the files written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written, entries = [], []
    for name, m in tiles:
        ortho, dem = out_dir / f"ortho{name}.png", out_dir / f"dem{name}.tif"
        write_raster(ortho, m.image, np.uint16)
        write_raster(dem, m.dem, np.float32)
        written += [ortho, dem]
        entries.append({"ortho": ortho.name, "dem": dem.name, "extent_m": list(m.image.extent_m())})
    first = tiles[0][1]
    meta = dict(metadata)
    meta.update(format=FORMAT, version=VERSION, tiles=entries,
                sun_direction_map=[float(v) for v in first.sun_direction_map],
                dem_sigma_m=first.dem_sigma_m, registration_sigma_m=first.registration_sigma_m,
                registration_sigma_rad=first.registration_sigma_rad, psf_sigma_px=first.psf_sigma_px)  # fmt: skip
    (out_dir / METADATA).write_text(json.dumps(meta, indent=2))
    written.append(out_dir / METADATA)
    return written


def read_products(out_dir: Path, tile: int = 0) -> OrbitalMap:
    """Tile ``tile`` of the products in ``out_dir`` as the localiser holds them."""
    path = Path(out_dir) / METADATA
    try:
        meta = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ConfigError(str(path), "(file)", f"cannot read the products' metadata ({err})") from None
    if meta.get("format") != FORMAT:
        raise ConfigError(str(path), "format", f"expected {FORMAT!r}, got {meta.get('format')!r}")
    entry = meta["tiles"][tile]
    return OrbitalMap(
        read_raster(Path(out_dir) / entry["ortho"]),
        read_raster(Path(out_dir) / entry["dem"]),
        np.asarray(meta["sun_direction_map"], dtype=float),
        float(meta["dem_sigma_m"]),
        float(meta["registration_sigma_m"]),
        float(meta["registration_sigma_rad"]),
        float(meta["psf_sigma_px"]),
    )


def spec_metadata(spec: object) -> dict:
    return asdict(spec) if hasattr(spec, "__dataclass_fields__") else spec.model_dump()  # type: ignore[attr-defined]
