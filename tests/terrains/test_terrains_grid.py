"""Terrain grid convention, queries, meshes and files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from terrains import (
    InvalidTerrainError,
    Material,
    MaterialSpec,
    RockSpec,
    SlopeSpec,
    Terrain,
    TerrainFileError,
    TerrainRecipe,
    synthesize,
)


def _plane(a: float = 0.3, b: float = -0.2, c: float = 1.5, shape: tuple[int, int] = (31, 41), cell: float = 0.1):
    nrow, ncol = shape
    xs = (np.arange(ncol) - (ncol - 1) / 2) * cell
    ys = (np.arange(nrow) - (nrow - 1) / 2) * cell
    return Terrain.from_heights(a * xs[None, :] + b * ys[:, None] + c, cell)


def test_grid_convention_is_mujoco_hfield() -> None:
    heights = np.zeros((5, 7))
    heights[0, 0] = 1.0  # south-west corner
    heights[4, 6] = 2.0  # north-east corner
    t = Terrain.from_heights(heights, 0.5)
    assert (t.nrow, t.ncol) == (5, 7)
    assert (t.half_x_m, t.half_y_m) == (1.5, 1.0)
    np.testing.assert_allclose(t.xs_m, [-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5])
    np.testing.assert_allclose(t.ys_m, [-1.0, -0.5, 0.0, 0.5, 1.0])
    assert t.height_at(-1.5, -1.0) == 1.0
    assert t.height_at(1.5, 1.0) == 2.0
    assert t.height_at(-1.25, -1.0) == pytest.approx(0.5)


def test_bilinear_height_is_exact_on_a_plane_and_clamps() -> None:
    t = _plane()
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-t.half_x_m, t.half_x_m, 1000), rng.uniform(-t.half_y_m, t.half_y_m, 1000)
    np.testing.assert_allclose(t.height_at(x, y), 0.3 * x - 0.2 * y + 1.5, atol=1e-12)
    grid_x, grid_y = np.meshgrid(x[:10], y[:20])  # broadcasting, any shape
    assert t.height_at(grid_x, grid_y).shape == (20, 10)
    assert isinstance(t.height_at(0.1, 0.2), float)
    assert t.height_at(100.0, 0.0) == pytest.approx(t.height_at(t.half_x_m, 0.0))
    assert t.height_at(-100.0, -100.0) == pytest.approx(t.heights_m[0, 0])


def test_normals_and_slope_on_a_plane() -> None:
    t = _plane(a=np.tan(np.radians(20.0)), b=0.0)
    n = t.normal_at(np.array([0.0, t.half_x_m, -50.0]), np.array([0.0, 0.0, 3.0]))
    expected = np.array([-np.sin(np.radians(20.0)), 0.0, np.cos(np.radians(20.0))])
    np.testing.assert_allclose(n, np.broadcast_to(expected, (3, 3)), atol=1e-12)
    assert t.slope_deg_at(0.3, -0.4) == pytest.approx(20.0)


def test_material_at_is_nearest_cell() -> None:
    materials = np.zeros((3, 3), dtype=np.uint8)
    materials[1, 2] = Material.BEDROCK
    t = Terrain(np.zeros((3, 3)), 1.0, materials)
    assert t.material_at(1.0, 0.0) == Material.BEDROCK
    assert t.material_at(0.6, 0.4) == Material.BEDROCK
    assert t.material_at(0.4, 0.0) == Material.SAND
    assert t.material_at(np.array([5.0, -5.0]), np.array([0.0, 0.0])).tolist() == [1, 0]


def test_save_load_round_trip_is_exact(tmp_path: Path) -> None:
    recipe = TerrainRecipe(
        size_m=(8, 6),
        cell_size_m=0.1,
        slope=SlopeSpec(slope_deg=15),
        rocks=RockSpec(cover_fraction=0.2),
        explicit_rocks=[{"name": "Wopmay", "x_m": 1.0, "y_m": 1.0, "length_m": 1.5, "width_m": 0.9, "height_m": 0.6}],
        material=MaterialSpec(kind="patches"),
    )
    t = synthesize(recipe, 42)
    path = t.save(tmp_path / "patch.npz")
    back = Terrain.load(path)
    assert back.heights_m.tobytes() == t.heights_m.tobytes()
    assert back.materials.tobytes() == t.materials.tobytes() and back.materials.dtype == np.uint8
    assert back.rocks == t.rocks
    assert back.recipe == t.recipe
    assert (back.seed, back.cell_size_m) == (42, 0.1)
    # arrays-only terrains round-trip too
    plain = _plane()
    again = Terrain.load(plain.save(tmp_path / "plane.npz"))
    assert again.recipe is None and np.array_equal(again.heights_m, plain.heights_m)


def test_loading_a_foreign_file_says_what_is_wrong(tmp_path: Path) -> None:
    path = tmp_path / "other.npz"
    np.savez(path, heights=np.zeros((3, 3)))
    with pytest.raises(TerrainFileError, match="Terrain.save"):
        Terrain.load(path)


def test_to_mesh() -> None:
    t = synthesize(TerrainRecipe(size_m=(4, 3), cell_size_m=0.1, material=MaterialSpec(kind="patches")), 0)
    mesh = t.to_mesh()
    assert len(mesh.vertices) == t.nrow * t.ncol
    assert len(mesh.faces) == 2 * (t.nrow - 1) * (t.ncol - 1)
    assert np.all(mesh.face_normals[:, 2] > 0)  # counter-clockwise seen from above
    np.testing.assert_allclose(mesh.bounds[:, :2], [[-2.0, -1.5], [2.0, 1.5]])
    assert mesh.visual.vertex_colors.shape == (len(mesh.vertices), 4)
    coarse = t.to_mesh(step=4)
    np.testing.assert_allclose(coarse.bounds[:, :2], mesh.bounds[:, :2])  # last row / column kept
    assert len(coarse.vertices) == len(np.unique(np.r_[0 : t.nrow : 4, t.nrow - 1])) * len(
        np.unique(np.r_[0 : t.ncol : 4, t.ncol - 1])
    )


@pytest.mark.parametrize(
    ("heights", "cell", "materials"),
    [
        (np.zeros(5), 0.1, np.zeros(5, dtype=np.uint8)),
        (np.zeros((3, 3)), 0.0, np.zeros((3, 3), dtype=np.uint8)),
        (np.zeros((3, 3)), 0.1, np.zeros((3, 4), dtype=np.uint8)),
        (np.zeros((3, 3)), 0.1, np.full((3, 3), 7, dtype=np.uint8)),
        (np.full((3, 3), np.nan), 0.1, np.zeros((3, 3), dtype=np.uint8)),
    ],
)
def test_invalid_terrains_raise(heights: np.ndarray, cell: float, materials: np.ndarray) -> None:
    with pytest.raises(InvalidTerrainError):
        Terrain(heights, cell, materials)
