"""Rocks: analytic shapes, meshes, the Golombek-Rapp law, placement and seating."""

from __future__ import annotations

import math
from itertools import combinations

import numpy as np
import pytest
from scipy.integrate import quad

from terrains import (
    Disc,
    InvalidRockError,
    Rock,
    RockSpec,
    RoughnessSpec,
    SlopeSpec,
    TerrainRecipe,
    synthesize,
)
from terrains.golombek import (
    cumulative_area_fraction,
    cumulative_number_per_m2,
    golombek_q_per_m,
    sample_diameters_m,
)
from terrains.synth import EMBED_MARGIN_M

SHAPES = ["hemispheroid", "semi_ellipsoid", "cone", "tetrahedron"]


def _rock(shape: str, **kw: float) -> Rock:
    width = 0.8 if shape == "hemispheroid" else 0.5
    params = {
        "x_m": 1.0,
        "y_m": -2.0,
        "z_base_m": 0.3,
        "length_m": 0.8,
        "width_m": width,
        "height_m": 0.4,
        "yaw_rad": 0.7,
        "buried_m": 0.1,
    } | kw
    return Rock(shape=shape, **params)  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------- single rocks


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("buried_m", [0.0, 0.1])
def test_mesh_is_watertight_convex_and_spans_the_rock(shape: str, buried_m: float) -> None:
    rock = _rock(shape, buried_m=buried_m)
    mesh = rock.mesh()
    assert mesh.is_watertight and mesh.is_convex
    assert len(mesh.vertices) <= 200
    assert mesh.vertices[:, 2].max() == pytest.approx(rock.z_base_m + rock.height_m)
    assert mesh.vertices[:, 2].min() == pytest.approx(rock.z_base_m - buried_m)
    assert mesh.volume == pytest.approx(rock.volume_m3, rel=0.06)
    assert mesh.volume <= rock.volume_m3 + 1e-12  # inscribed polygons
    horizontal = np.hypot(mesh.vertices[:, 0] - rock.x_m, mesh.vertices[:, 1] - rock.y_m)
    assert horizontal.max() == pytest.approx(rock.footprint_radius_m, rel=1e-9)


@pytest.mark.parametrize("shape", SHAPES)
def test_analytic_top_surface_matches_the_mesh(shape: str) -> None:
    rock = _rock(shape)
    top = rock.mesh().vertices
    top = top[top[:, 2] >= rock.z_base_m - 1e-12]
    np.testing.assert_allclose(rock.top_z_at(top[:, 0], top[:, 1]), top[:, 2], atol=1e-9)
    assert rock.top_z_at(rock.x_m, rock.y_m) == pytest.approx(rock.z_base_m + rock.height_m)
    far = rock.top_z_at(rock.x_m + 1.01 * rock.footprint_radius_m, rock.y_m)
    assert np.isnan(far)


def test_footprint_extents_follow_length_width_and_yaw() -> None:
    rock = _rock("semi_ellipsoid", yaw_rad=math.pi / 2)  # length along north
    outline = rock.footprint_xy_m(64)
    assert np.ptp(outline[:, 1]) == pytest.approx(rock.length_m, rel=1e-6)
    assert np.ptp(outline[:, 0]) == pytest.approx(rock.width_m, rel=1e-2)
    tet = _rock("tetrahedron", yaw_rad=0.0)
    tri = tet.footprint_xy_m()
    assert np.ptp(tri[:, 0]) == pytest.approx(tet.length_m) and np.ptp(tri[:, 1]) == pytest.approx(tet.width_m)
    np.testing.assert_allclose(tri.mean(axis=0), [tet.x_m, tet.y_m], atol=1e-12)  # centre = centroid


def test_volumes_and_areas() -> None:
    r = _rock("semi_ellipsoid", buried_m=0.0)
    assert r.volume_m3 == pytest.approx(2 / 3 * math.pi * 0.4 * 0.25 * 0.4)
    assert r.equivalent_diameter_m == pytest.approx(math.sqrt(0.8 * 0.5))
    t = _rock("tetrahedron", buried_m=0.1)
    assert t.footprint_area_m2 == pytest.approx(0.2)
    assert t.volume_m3 == pytest.approx(0.2 * 0.4 / 3 + 0.2 * 0.1)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"shape": "hemispheroid", "length_m": 1.0, "width_m": 0.6},
        {"shape": "pyramid"},
        {"height_m": 0.0},
        {"buried_m": -0.1},
        {"x_m": float("nan")},
    ],
)
def test_invalid_rocks_raise(kwargs: dict) -> None:
    params = {
        "x_m": 0.0,
        "y_m": 0.0,
        "z_base_m": 0.0,
        "shape": "cone",
        "length_m": 1.0,
        "width_m": 1.0,
        "height_m": 0.5,
    } | kwargs
    with pytest.raises(InvalidRockError):
        Rock(**params)


# ----------------------------------------------------------------------------------------- Golombek-Rapp


def test_cumulative_number_is_the_integral_of_the_size_density() -> None:
    k, d0 = 0.12, 0.15
    q = golombek_q_per_m(k)
    numeric, _ = quad(lambda d: 4 * k * q * math.exp(-q * d) / (math.pi * d * d), d0, np.inf)
    assert float(cumulative_number_per_m2(d0, k)) == pytest.approx(numeric, rel=1e-8)
    assert q == pytest.approx(1.79 + 0.152 / 0.12)


def _covered_area_std_m2(d_m: float, k: float, area_m2: float) -> float:
    """Std of the area covered by rocks >= D on ``area_m2`` (compound Poisson: A * integral of n(D)
    a(D)^2)."""
    q = golombek_q_per_m(k)
    second_moment, _ = quad(
        lambda d: 4 * k * q * math.exp(-q * d) / (math.pi * d * d) * (math.pi * d * d / 4) ** 2, d_m, np.inf
    )
    return math.sqrt(area_m2 * second_moment)


def test_rock_cover_follows_golombek_rapp() -> None:
    """On 3600 m^2 the area fraction covered by rocks >= D matches F_k(D) = k exp(-q D) within 4 sigma."""
    k = 0.15
    spec = RockSpec(cover_fraction=k, min_height_m=0.1, height_to_diameter=(0.5, 0.5), exclusion_zones=[])
    recipe = TerrainRecipe(size_m=(60, 60), cell_size_m=0.5, roughness=RoughnessSpec(rms_m=0.0), rocks=spec)
    t = synthesize(recipe, 11)
    area_m2 = 60.0 * 60.0
    diameters = np.array([r.equivalent_diameter_m for r in t.rocks])
    areas = np.array([r.footprint_area_m2 for r in t.rocks])
    assert diameters.min() >= spec.min_diameter_m - 1e-12
    expected_count = spec.expected_count(area_m2)
    assert abs(len(t.rocks) - expected_count) < 4 * math.sqrt(expected_count)
    for d in (0.2, 0.3, 0.5, 0.8, 1.2):
        covered_m2 = areas[diameters >= d].sum()
        expected_m2 = float(cumulative_area_fraction(d, k)) * area_m2
        assert abs(covered_m2 - expected_m2) < 4 * _covered_area_std_m2(d, k, area_m2), d
    # a much larger sample of the size law alone pins the shape down tightly
    sizes = sample_diameters_m(k, 0.2, 2.0e5, np.random.default_rng(0))
    for d in (0.2, 0.5, 1.0):
        fraction = (math.pi / 4 * sizes[sizes >= d] ** 2).sum() / 2.0e5
        assert fraction == pytest.approx(float(cumulative_area_fraction(d, k)), rel=0.05)


def test_rock_heights_are_about_half_the_diameter_and_clipped() -> None:
    spec = RockSpec(cover_fraction=0.3, min_height_m=0.15, max_height_m=0.4, exclusion_zones=[])
    t = synthesize(TerrainRecipe(size_m=(20, 20), cell_size_m=0.25, rocks=spec), 2)
    heights = np.array([r.height_m for r in t.rocks])
    ratio = heights / np.array([r.equivalent_diameter_m for r in t.rocks])
    assert heights.min() >= 0.15 and heights.max() <= 0.4
    assert np.any(heights == 0.4)
    unclipped = (heights > 0.15) & (heights < 0.4)
    assert np.all((ratio[unclipped] >= 0.4 - 1e-12) & (ratio[unclipped] <= 0.6 + 1e-12))
    assert {r.shape for r in t.rocks} == set(SHAPES)


def test_no_cover_no_rocks() -> None:
    assert (
        synthesize(TerrainRecipe(size_m=(10, 10), cell_size_m=0.2, rocks=RockSpec(cover_fraction=0.0)), 0).rocks == []
    )


# -------------------------------------------------------------------------------------------- placement


def test_rocks_do_not_overlap_and_respect_exclusion_zones() -> None:
    zones = [Disc(0.0, 0.0, 2.0), Disc(5.0, -4.0, 1.5)]
    spec = RockSpec(cover_fraction=0.35, min_height_m=0.08, exclusion_zones=zones)
    wopmay = {"name": "Wopmay", "x_m": -4.0, "y_m": 4.0, "length_m": 1.5, "width_m": 0.9, "height_m": 0.6}
    t = synthesize(TerrainRecipe(size_m=(16, 14), cell_size_m=0.1, rocks=spec, explicit_rocks=[wopmay]), 5)
    assert len(t.rocks) > 100
    for a, b in combinations(t.rocks, 2):
        assert math.hypot(a.x_m - b.x_m, a.y_m - b.y_m) >= a.footprint_radius_m + b.footprint_radius_m - 1e-9
    for rock in t.rocks[1:]:
        for z in zones:
            assert math.hypot(rock.x_m - z.x_m, rock.y_m - z.y_m) >= z.radius_m + rock.footprint_radius_m - 1e-9
        assert abs(rock.x_m) + rock.footprint_radius_m <= t.half_x_m + 1e-9
        assert abs(rock.y_m) + rock.footprint_radius_m <= t.half_y_m + 1e-9
    assert len({r.name for r in t.rocks}) == len(t.rocks)


def test_explicit_rock_is_placed_as_named() -> None:
    wopmay = {
        "name": "Wopmay",
        "x_m": 2.0,
        "y_m": -3.0,
        "length_m": 1.5,
        "width_m": 0.9,
        "height_m": 0.6,
        "yaw_deg": 30.0,
    }
    recipe = TerrainRecipe(
        size_m=(10, 10),
        cell_size_m=0.05,
        slope=SlopeSpec(slope_deg=18.0, azimuth_deg=90.0),
        explicit_rocks=[wopmay],
    )
    t = synthesize(recipe, 0)
    rock = next(r for r in t.rocks if r.name == "Wopmay")
    assert (rock.length_m, rock.width_m, rock.height_m) == (1.5, 0.9, 0.6)
    assert rock.yaw_rad == pytest.approx(math.radians(30.0))
    assert rock.z_base_m == pytest.approx(float(t.height_at(2.0, -3.0)))
    assert float(t.height_with_rocks_at(2.0, -3.0)) == pytest.approx(rock.z_base_m + 0.6)


def test_rocks_are_seated_flush_on_slopes() -> None:
    recipe = TerrainRecipe(
        size_m=(20, 20),
        cell_size_m=0.1,
        slope=SlopeSpec(slope_deg=25.0, azimuth_deg=10.0),
        rocks=RockSpec(cover_fraction=0.1, buried_fraction=(0.0, 0.0)),
    )
    t = synthesize(recipe, 1)
    assert t.rocks
    for rock in t.rocks:
        outline = rock.footprint_xy_m(32)
        lowest = float(np.min(t.height_at(outline[:, 0], outline[:, 1])))
        assert rock.z_base_m - rock.buried_m <= lowest - EMBED_MARGIN_M + 1e-3
        assert rock.z_base_m == pytest.approx(float(t.height_at(rock.x_m, rock.y_m)))


def test_height_with_rocks_at_rock_centres_and_between() -> None:
    t = synthesize(TerrainRecipe(size_m=(20, 20), cell_size_m=0.1, rocks=RockSpec(cover_fraction=0.2)), 3)
    cx = np.array([r.x_m for r in t.rocks])
    cy = np.array([r.y_m for r in t.rocks])
    tops = np.array([r.z_base_m + r.height_m for r in t.rocks])
    np.testing.assert_allclose(t.height_with_rocks_at(cx, cy), tops, atol=1e-12)
    # many points at once (exercises the KD-tree path) agree with a per-rock brute force
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-10, 10, 60_000), rng.uniform(-10, 10, 60_000)
    expected = t.height_at(x, y)
    for rock in t.rocks:
        expected = np.fmax(expected, rock.top_z_at(x, y))
    np.testing.assert_allclose(t.height_with_rocks_at(x, y), expected, atol=1e-12)
    assert np.all(t.height_with_rocks_at(x, y) >= t.height_at(x, y))
