"""Multi-scale regolith texture (terrains.regolith): a function of world coordinates, tileable, lit by the sun."""

from __future__ import annotations

import numpy as np
import pytest

from terrains import RockSpec, TerrainRecipe, albedo_texture, albedo_tile, synthesize
from terrains.appearance import FINE_SOIL_FACTOR

SUN = np.array([-0.6, 0.2, -0.77]) / np.linalg.norm([-0.6, 0.2, -0.77])


@pytest.mark.parametrize("sun", [None, SUN])
def test_adjacent_tiles_join_seamlessly_and_equal_the_whole(sun):
    whole = albedo_tile(-3.0, 1.0, 300, 240, 100.0, seed=9, sun_direction=sun)
    quads = [
        [albedo_tile(-3.0 + 1.5 * i, 1.0 + 1.2 * j, 150, 120, 100.0, seed=9, sun_direction=sun) for i in (0, 1)]
        for j in (0, 1)
    ]
    np.testing.assert_allclose(np.block(quads), whole, atol=1e-6)
    assert not np.allclose(whole, albedo_tile(-3.0, 1.0, 300, 240, 100.0, seed=10, sun_direction=sun))


def test_the_site_texture_is_the_tile_function_on_the_site_grid():
    terrain = synthesize(TerrainRecipe(size_m=(4.0, 4.0), cell_size_m=0.05, rocks=RockSpec(cover_fraction=0.0)), 3)
    site = albedo_texture(terrain, 100.0, 3, regolith="multiscale", sun_direction=SUN)
    np.testing.assert_allclose(site, albedo_tile(-2.0, -2.0, 400, 400, 100.0, 3, sun_direction=SUN), atol=1e-5)
    classic = albedo_texture(terrain, 100.0, 3)
    assert not np.allclose(site, classic)


def test_texture_has_several_scales_and_the_relief_depends_on_the_sun():
    flat = albedo_tile(0.0, 0.0, 400, 400, 100.0, seed=1)
    low_east = albedo_tile(0.0, 0.0, 400, 400, 100.0, seed=1, sun_direction=np.array([-0.95, 0.0, -0.31]))
    high_west = albedo_tile(0.0, 0.0, 400, 400, 100.0, seed=1, sun_direction=np.array([0.5, 0.0, -0.87]))
    assert np.abs(low_east - high_west).mean() > 0.02  # the micro-relief is lit differently
    assert abs(low_east.mean() - high_west.mean()) < 0.05  # ... around the same mean albedo
    # power at pebble (~2 cm), clast (~10 cm) and mottle (~0.5 m) scales: every octave carries texture
    spectrum = np.abs(np.fft.rfft2(flat - flat.mean())) ** 2
    k = np.hypot(np.fft.fftfreq(400)[:, None], np.fft.rfftfreq(400)[None, :]) * 100.0  # cycles per metre
    for lo, hi in [(1.0, 4.0), (5.0, 20.0), (25.0, 50.0)]:
        assert spectrum[(k >= lo) & (k < hi)].mean() > 1e-3 * spectrum[k > 0].mean()


def test_fine_soil_detail_starves_the_texture():
    ordinary = albedo_tile(0.0, 0.0, 300, 300, 100.0, seed=4, sun_direction=SUN)
    fine = albedo_tile(0.0, 0.0, 300, 300, 100.0, seed=4, sun_direction=SUN, detail=FINE_SOIL_FACTOR)
    grad = lambda a: np.abs(np.diff(a, axis=1)).mean()  # noqa: E731 - what a correlator sees
    assert grad(fine) < 0.12 * grad(ordinary)
    assert fine.std() < 0.1 * ordinary.std()
