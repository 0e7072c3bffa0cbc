"""Procedural albedo textures."""

from __future__ import annotations

import numpy as np
import pytest

from terrains import (
    MaterialSpec,
    RockSpec,
    TerrainRecipe,
    albedo_texture,
    rock_albedo,
    synthesize,
    texture_rgb_u8,
)


def _terrain(kind: str, size: float = 4.0):
    recipe = TerrainRecipe(
        size_m=(size, size),
        cell_size_m=0.1,
        material=MaterialSpec(kind=kind),
        rocks=RockSpec(cover_fraction=0.2),
    )
    return synthesize(recipe, 0)


def _band_pass_std(a: np.ndarray) -> float:
    """Std of the texture detail that stereo matching uses (difference of neighbours)."""
    return float(np.std(np.diff(a, axis=1)))


def test_shape_dtype_range_and_determinism() -> None:
    t = _terrain("patches", size=6.0)
    a = albedo_texture(t, 40.0, seed=3)
    assert a.shape == (240, 240) and a.dtype == np.float32
    assert 0.0 <= a.min() and a.max() <= 1.0
    assert np.array_equal(a, albedo_texture(t, 40.0, seed=3))
    assert not np.array_equal(a, albedo_texture(t, 40.0, seed=4))


def test_fine_soil_is_nearly_featureless() -> None:
    t = _terrain("sand")
    normal = albedo_texture(t, 100.0, seed=0)
    fine = albedo_texture(t, 100.0, seed=0, fine_soil=True)
    assert _band_pass_std(fine) < 0.1 * _band_pass_std(normal)
    assert fine.std() < 0.01
    flat = albedo_texture(t, 100.0, seed=0, contrast=0.0)
    assert np.ptp(flat) < 1e-6


def test_bedrock_has_more_contrast_than_sand_and_mixed_is_between() -> None:
    stds = {kind: albedo_texture(_terrain(kind), 100.0, seed=0).std() for kind in ("sand", "mixed", "bedrock")}
    assert stds["sand"] < stds["mixed"] < stds["bedrock"]


def test_patches_follow_the_material_map() -> None:
    t = _terrain("patches", size=10.0)
    a = albedo_texture(t, 20.0, seed=0)
    # pixel (r, c) lies at x = -half_x + (c + 0.5) / ppm, y = -half_y + (r + 0.5) / ppm
    ys = -t.half_y_m + (np.arange(a.shape[0]) + 0.5) / 20.0
    xs = -t.half_x_m + (np.arange(a.shape[1]) + 0.5) / 20.0
    mat = t.material_at(*np.meshgrid(xs, ys))
    assert a[mat == 0].mean() > a[mat == 1].mean()  # sand brighter than outcrop


def test_rgb_texture_and_rock_albedo() -> None:
    rgb = texture_rgb_u8(np.array([[0.0, 1.0]], dtype=np.float32))
    assert rgb.dtype == np.uint8 and rgb.shape == (1, 2, 3)
    assert rgb[0, 0].tolist() == [0, 0, 0]
    assert rgb[0, 1].tolist() == [194, 140, 102]  # butterscotch
    t = _terrain("sand")
    assert t.rocks
    grey = [rock_albedo(r, 1) for r in t.rocks]
    assert all(0.25 <= g <= 0.6 for g in grey)
    assert grey == [rock_albedo(r, 1) for r in t.rocks]
    assert len(set(grey)) > 1


def test_bad_arguments() -> None:
    t = _terrain("sand")
    with pytest.raises(ValueError, match="px_per_m"):
        albedo_texture(t, 0.0, seed=0)
    with pytest.raises(ValueError, match="contrast"):
        albedo_texture(t, 10.0, seed=0, contrast=-1.0)
