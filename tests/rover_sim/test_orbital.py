"""Orbital products: written as north-up rasters with world files, read back by GDAL (rasterio) with the right
georeference; the registration error moves the whole map; streamed sites give tiles along the route."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rover_sim.orbital.files import read_products, write_products
from rover_sim.orbital.products import make_products, site_boxes
from rover_sim.scenario.loading import load_scenario, scenario_from_dict

ROCK_XY = (2.0, -3.0)


def site(registration_sigma_m: float = 0.0, dem_sigma_m: float = 0.0) -> object:
    return scenario_from_dict({
        "name": "orbital_test", "seed": 7,
        "terrain": {"size_m": [16, 16], "cell_size_m": 0.1, "rocks": {"cover_fraction": 0.0},
                    "roughness": {"rms_m": 0.005},
                    "explicit_rocks": [{"name": "big", "x_m": ROCK_XY[0], "y_m": ROCK_XY[1], "shape": "hemispheroid",
                                        "length_m": 1.4, "width_m": 1.4, "height_m": 0.7}]},
        "orbital": {"registration_sigma_m": registration_sigma_m, "registration_sigma_deg": 0.0,
                    "dem_sigma_m": dem_sigma_m},
        "commands": [{"type": "drive", "distance_m": 0.1}],
    })  # fmt: skip


def test_products_read_back_with_rasterio_georeferenced(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    sc = site()
    omap, _reg = make_products(sc, site_boxes(sc)[0])
    write_products(tmp_path, [("", omap)], {"scenario": sc.name})
    with rasterio.open(tmp_path / "dem.tif") as dem, rasterio.open(tmp_path / "ortho.png") as ortho:
        assert dem.transform.a == pytest.approx(1.0) and dem.transform.e == pytest.approx(-1.0)
        assert ortho.transform.a == pytest.approx(0.25) and ortho.transform.e == pytest.approx(-0.25)
        assert ortho.dtypes[0] == "uint16" and dem.dtypes[0] == "float32"
        z = dem.read(1)
        r, c = np.unravel_index(int(np.argmax(z)), z.shape)
        x, y = dem.xy(r, c)  # pixel centre in the site frame
        assert math.hypot(x - ROCK_XY[0], y - ROCK_XY[1]) <= 1.0
        # the image's north-west corner and the DEM's agree (both cover the site)
        assert abs(ortho.bounds.left - dem.bounds.left) < 0.5 and abs(ortho.bounds.top - dem.bounds.top) < 0.5
    back = read_products(tmp_path)
    assert np.array_equal(back.dem.values, omap.dem.values)
    assert back.image.x0_m == pytest.approx(omap.image.x0_m) and back.image.y0_m == pytest.approx(omap.image.y0_m)
    meta = json.loads((tmp_path / "orbital.json").read_text())
    assert meta["tiles"][0]["ortho"] == "ortho.png"


def test_registration_error_moves_the_map():
    sc = site(registration_sigma_m=2.0)
    omap, reg = make_products(sc, site_boxes(sc)[0])
    d = omap.dem
    r, c = np.unravel_index(int(np.nanargmax(d.values)), d.values.shape)
    x_map, y_map = d.x0_m + c * d.px_m, d.y0_m + r * d.px_m
    # the rock shows where the map frame says site point ROCK_XY is: p_map = p_site - t (no rotation drawn)
    want = (ROCK_XY[0] - reg.offset_xy_m[0], ROCK_XY[1] - reg.offset_xy_m[1])
    assert math.hypot(*reg.offset_xy_m) > 0.5
    assert math.hypot(x_map - want[0], y_map - want[1]) <= 1.0
    again, reg2 = make_products(sc, site_boxes(sc)[0])
    assert reg2 == reg and np.array_equal(again.image.values, omap.image.values)  # seeded


def test_streamed_site_gives_tiles_along_the_route():
    sc = load_scenario("spirit_plains_sol")
    boxes = site_boxes(sc)
    assert sc.terrain.streamed is not None and len(boxes) > 1
    xs = [b.x0_m for b in boxes]
    assert max(xs) - min(xs) > 100.0  # along the route, not a square around the start


def test_cli_writes_products_and_refuses_a_bad_field(tmp_path):
    from typer.testing import CliRunner

    from rover_sim.cli.main import app

    toml = tmp_path / "tiny.toml"
    toml.write_text('name = "tiny"\n[terrain]\nsize_m = [12, 12]\ncell_size_m = 0.1\n[terrain.rocks]\n'
                    'cover_fraction = 0.02\n[[commands]]\ntype = "drive"\ndistance_m = 0.1\n')  # fmt: skip
    out = tmp_path / "orb"
    res = CliRunner().invoke(app, ["orbital", str(toml), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert {p.name for p in out.iterdir()} >= {"ortho.png", "ortho.pgw", "dem.tif", "dem.tfw", "orbital.json"}
    res = CliRunner().invoke(app, ["orbital", str(toml), "--out", str(tmp_path / "x"), "--set",
                                   "orbital.dem_sigma_m=-1"])  # fmt: skip
    assert res.exit_code == 2 and "orbital.dem_sigma_m" in res.output


@pytest.mark.slow
def test_streamed_tile_products_are_made_from_world_coordinates():
    from rover_sim.orbital.products import Box

    sc = load_scenario("spirit_plains_sol")
    omap, _ = make_products(sc, Box(10.125, -9.875, 16.0, 16.0))
    assert omap.image.shape == (64, 64) and omap.dem.shape == (16, 16)
    assert np.all(np.isfinite(omap.dem.values)) and omap.image.values.std() > 0
