"""Irregular rocks (terrains/rock_shapes.py): off by default, seeded, geometrically consistent, saved and loaded."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from terrains import IRREGULAR_FORMS, IrregularRock, RockSpec, Terrain, TerrainRecipe, rock_class, synthesize


def recipe(fraction: float | None) -> TerrainRecipe:
    extra = {} if fraction is None else {"irregular_fraction": fraction}
    return TerrainRecipe(
        size_m=(16.0, 16.0),
        cell_size_m=0.05,
        rocks=RockSpec(cover_fraction=0.08, min_height_m=0.1, max_height_m=0.6, **extra),
    )


@pytest.fixture(scope="module")
def mixed() -> Terrain:
    return synthesize(recipe(0.5), 3)


def test_default_is_todays_analytic_rocks() -> None:
    default, zero = synthesize(recipe(None), 3), synthesize(recipe(0.0), 3)
    assert default.rocks == zero.rocks
    assert all(rock_class(r) == "analytic" for r in default.rocks)


def test_mix_keeps_placement_and_draws_every_form(mixed: Terrain) -> None:
    analytic = synthesize(recipe(0.0), 3)
    assert [(r.x_m, r.y_m, r.yaw_rad) for r in mixed.rocks] == [(r.x_m, r.y_m, r.yaw_rad) for r in analytic.rocks]
    irregular = [r for r in mixed.rocks if rock_class(r) == "irregular"]
    assert 0.35 < len(irregular) / len(mixed.rocks) < 0.65
    assert {r.shape for r in irregular} == set(IRREGULAR_FORMS)
    again = synthesize(recipe(0.5), 3)
    assert again.rocks == mixed.rocks  # seeded


def test_irregular_geometry_is_consistent(mixed: Terrain) -> None:
    for rock in [r for r in mixed.rocks if isinstance(r, IrregularRock)][:30]:
        mesh = rock.mesh()
        assert mesh.is_watertight and mesh.is_convex
        assert mesh.vertices[:, 2].max() == pytest.approx(rock.z_base_m + rock.height_m, abs=1e-9)
        assert mesh.vertices[:, 2].min() == pytest.approx(rock.z_base_m - rock.buried_m, abs=1e-9)
        horizontal = np.hypot(mesh.vertices[:, 0] - rock.x_m, mesh.vertices[:, 1] - rock.y_m)
        assert horizontal.max() <= rock.footprint_radius_m + 1e-9
        assert rock.footprint_radius_m <= 0.5 * max(rock.length_m, rock.width_m) + 1e-9  # inside the analytic one
        g = np.linspace(-1.0, 1.0, 121) * rock.footprint_radius_m
        x, y = np.meshgrid(rock.x_m + g, rock.y_m + g)
        z = rock.top_z_at(x, y)
        assert np.nanmax(z) <= rock.z_base_m + rock.height_m + 1e-9
        assert np.nanmax(z) >= rock.z_base_m + 0.9 * rock.height_m
        # the top surface is the mesh's: a point just above it is outside the mesh, just below inside
        inside = np.isfinite(z) & (z > rock.z_base_m + 0.02)  # (near the outline an overhang may be thinner)
        inside &= np.hypot(x - rock.x_m, y - rock.y_m) < 0.5 * rock.footprint_radius_m
        pts = np.column_stack([x[inside], y[inside], z[inside]])[::7]
        eq = ConvexHull(mesh.vertices).equations

        def contains(p: np.ndarray, eq: np.ndarray = eq) -> np.ndarray:
            return np.all(p @ eq[:, :3].T + eq[:, 3] <= 1e-9, axis=1)

        assert not contains(pts + [0.0, 0.0, 0.01]).any()
        assert contains(pts - [0.0, 0.0, 0.01]).all()
        assert np.isnan(rock.top_z_at(rock.x_m + 2.0 * rock.footprint_radius_m, rock.y_m))


def test_height_with_rocks_sees_irregular_tops(mixed: Terrain) -> None:
    rocks = [r for r in mixed.rocks if isinstance(r, IrregularRock)]
    x, y = np.array([r.x_m for r in rocks]), np.array([r.y_m for r in rocks])
    h = mixed.height_with_rocks_at(x, y)
    own = np.array([r.top_z_at(r.x_m, r.y_m) for r in rocks])
    assert np.all(h >= np.where(np.isfinite(own), own, -np.inf) - 1e-9)
    assert np.mean(h > mixed.height_at(x, y) + 0.05) > 0.9


def test_save_and_load_keep_irregular_rocks(mixed: Terrain, tmp_path) -> None:  # noqa: ANN001
    mixed.save(tmp_path / "t.npz")
    assert Terrain.load(tmp_path / "t.npz").rocks == mixed.rocks


def test_bad_fraction_is_rejected() -> None:
    with pytest.raises(ValueError, match="irregular_fraction"):
        RockSpec(irregular_fraction=1.5)
