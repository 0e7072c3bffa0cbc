"""Terrain and rock data types: a heightfield grid, a material map and a list of analytic rocks.

Frame: world x east, y north, z up. **Grid convention (MuJoCo hfield)**: the grid is centred on the world
origin; row ``i`` lies at ``y = -half_y + i * cell`` and column ``j`` at ``x = -half_x + j * cell``, with
``half_x = (ncol - 1) * cell / 2`` and ``half_y = (nrow - 1) * cell / 2``. So ``heights_m[0, 0]`` is the
south-west corner and ``heights_m[-1, -1]`` the north-east corner; MuJoCo's ``hfield`` size is ``(half_x,
half_y, ...)``.

Rocks are the four analytic models the rock-based cross-site localisation work fits to stereo points (Li, Di,
Agarwal, Wang, Matthies, Howard, "Automation of ground image based Mars rover localization"): hemispheroid,
semi-ellipsoid, cone and tetrahedron. Above the ground the rock *is* the model (so a rock's parameters are its
ground truth for rock extraction and matching); below the ground it continues as a vertical skirt of its
footprint, ``buried_m`` deep, which keeps the rock flush with sloping or rough ground.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from enum import IntEnum
from pathlib import Path
from typing import get_args

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from terrains.errors import InvalidRockError, InvalidTerrainError, TerrainFileError
from terrains.recipe import RockShape, TerrainRecipe

FILE_FORMAT = "rover-sim-terrain"
FILE_VERSION = 1

_SHAPE_CODES: dict[str, int] = {name: code for code, name in enumerate(get_args(RockShape))}

# Mesh resolution of the curved rock models (vertex budget <= 200 per rock).
_ELLIPSOID_AZIMUTHS = 24  # vertices per latitude ring
_ELLIPSOID_RINGS = 6  # latitude rings from the base up (the apex is added)
_CONE_AZIMUTHS = 32
_OUTLINE_TOLERANCE = 1e-12  # points this close outside the outline (normalised units) count as on it

# Tetrahedron footprint in normalised coordinates (u / (L/2), v / (W/2)), centroid at the origin: the extent
# along the rock's x is L and along its y is W; the apex stands above the centroid.
_TETRA_BASE_N = np.array([[4.0 / 3.0, 0.0], [-2.0 / 3.0, 1.0], [-2.0 / 3.0, -1.0]])


class Material(IntEnum):
    """Ground material of a heightfield cell (stored as ``uint8``)."""

    SAND = 0  # loose aeolian sand / soil: deforms, slips (Eagle crater, ripples)
    BEDROCK = 1  # outcrop: hard, little slip even at 20 deg
    MIXED = 2  # thin sand over rock, or gravel: in between
    DRIFT = 3  # loose, fine-grained, porous drift (Purgatory ripple): only the experimental Wong-Reece law has it


# --------------------------------------------------------------------------------------------------- rocks


@dataclass(frozen=True)
class Rock:
    """One rock, an analytic convex shape standing on the ground.

    ``(x_m, y_m)`` is the centre (for the tetrahedron: the footprint centroid, under the apex); ``z_base_m``
    the ground height there. ``length_m`` and ``width_m`` are the full extents of the footprint at ground
    level along the rock's own x and y (x rotated by ``yaw_rad`` from world +x), ``height_m`` the visible
    height above the ground at the centre, and ``buried_m`` the depth of the skirt below ground: the shape
    spans ``z_base_m - buried_m`` to ``z_base_m + height_m``. A hemispheroid is a spheroid of revolution, so
    its ``length_m`` equals its ``width_m``.
    """

    x_m: float
    y_m: float
    z_base_m: float
    shape: RockShape
    length_m: float
    width_m: float
    height_m: float
    yaw_rad: float = 0.0
    buried_m: float = 0.0
    name: str = ""

    def __post_init__(self) -> None:
        if self.shape not in _SHAPE_CODES:
            raise InvalidRockError(f"unknown rock shape {self.shape!r}; use one of {tuple(_SHAPE_CODES)}")
        values = (self.x_m, self.y_m, self.z_base_m, self.length_m, self.width_m, self.height_m)
        if not all(math.isfinite(v) for v in (*values, self.yaw_rad, self.buried_m)):
            raise InvalidRockError(f"rock {self.name!r} has a non-finite coordinate or size: {self}")
        if min(self.length_m, self.width_m, self.height_m) <= 0.0:
            raise InvalidRockError(f"rock {self.name!r}: length_m, width_m and height_m must be > 0 ({self})")
        if self.buried_m < 0.0:
            raise InvalidRockError(f"rock {self.name!r}: buried_m must be >= 0, got {self.buried_m}")
        if self.shape == "hemispheroid" and not math.isclose(self.length_m, self.width_m, rel_tol=1e-9):
            raise InvalidRockError(
                f"rock {self.name!r}: a hemispheroid has a round footprint; set length_m == width_m "
                "or use shape='semi_ellipsoid'"
            )

    # -- geometry --------------------------------------------------------------------------------------------

    @property
    def footprint_area_m2(self) -> float:
        """Area of the footprint at ground level (ellipse ``pi L W / 4``; triangle ``L W / 2``)."""
        if self.shape == "tetrahedron":
            return 0.5 * self.length_m * self.width_m
        return 0.25 * math.pi * self.length_m * self.width_m

    @property
    def equivalent_diameter_m(self) -> float:
        """Diameter of the circle with the footprint's area (the ``D`` of the Golombek-Rapp law)."""
        return math.sqrt(4.0 * self.footprint_area_m2 / math.pi)

    @property
    def footprint_radius_m(self) -> float:
        """Radius of the smallest circle about ``(x_m, y_m)`` that contains the footprint (and the skirt)."""
        if self.shape == "tetrahedron":
            return max(2.0 * self.length_m / 3.0, math.hypot(self.length_m / 3.0, self.width_m / 2.0))
        return 0.5 * max(self.length_m, self.width_m)

    @property
    def visible_volume_m3(self) -> float:
        """Volume above the ground plane through the base (the fitted model's volume)."""
        if self.shape in ("hemispheroid", "semi_ellipsoid"):
            return 2.0 / 3.0 * self.footprint_area_m2 * self.height_m
        return self.footprint_area_m2 * self.height_m / 3.0  # cone and tetrahedron: base area x height / 3

    @property
    def volume_m3(self) -> float:
        """Volume of the whole shape, visible dome plus buried skirt (what :meth:`mesh` encloses)."""
        return self.visible_volume_m3 + self.footprint_area_m2 * self.buried_m

    def top_z_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        """World height of the rock's top surface at ``(x, y)``; NaN outside the footprint. Vectorised."""
        x, y = np.broadcast_arrays(np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64))
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        dx, dy = x - self.x_m, y - self.y_m
        un = (c * dx + s * dy) * (2.0 / self.length_m)
        vn = (-s * dx + c * dy) * (2.0 / self.width_m)
        frac = _dome_fraction(_SHAPE_CODES[self.shape], un, vn)
        return _scalar_or_array(self.z_base_m + self.height_m * frac)

    def footprint_xy_m(self, n: int = 16) -> np.ndarray:
        """``(k, 2)`` world points on the footprint outline at ground level (``n`` for curved shapes, 3
        else)."""
        local = self._base_outline_local(n)
        return self._to_world(np.column_stack([local, np.zeros(len(local))]))[:, :2]

    def mesh(self) -> trimesh.Trimesh:
        """Watertight convex mesh of the whole rock in world coordinates (at most 200 vertices)."""
        a, b, h = 0.5 * self.length_m, 0.5 * self.width_m, self.height_m
        if self.shape in ("hemispheroid", "semi_ellipsoid"):
            az = np.linspace(0.0, 2.0 * np.pi, _ELLIPSOID_AZIMUTHS, endpoint=False)
            el = np.linspace(0.0, 0.5 * np.pi, _ELLIPSOID_RINGS, endpoint=False)
            ring_scale, ring_z = np.cos(el)[:, None], h * np.sin(el)[:, None]
            dome = np.stack(
                [
                    a * ring_scale * np.cos(az),
                    b * ring_scale * np.sin(az),
                    np.broadcast_to(ring_z, (len(el), len(az))),
                ],
                axis=-1,
            ).reshape(-1, 3)
            top = np.vstack([dome, [[0.0, 0.0, h]]])
        else:
            outline = self._base_outline_local(_CONE_AZIMUTHS)
            top = np.vstack([np.column_stack([outline, np.zeros(len(outline))]), [[0.0, 0.0, h]]])
        if self.buried_m > 1e-9:
            outline = self._base_outline_local(
                _ELLIPSOID_AZIMUTHS if self.shape != "cone" else _CONE_AZIMUTHS
            )
            skirt = np.column_stack([outline, np.full(len(outline), -self.buried_m)])
            top = np.vstack([top, skirt])
        hull = trimesh.convex.convex_hull(self._to_world(top))
        return hull

    def _base_outline_local(self, n: int) -> np.ndarray:
        a, b = 0.5 * self.length_m, 0.5 * self.width_m
        if self.shape == "tetrahedron":
            return _TETRA_BASE_N * np.array([a, b])
        az = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        return np.column_stack([a * np.cos(az), b * np.sin(az)])

    def _to_world(self, local_xyz: np.ndarray) -> np.ndarray:
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return local_xyz @ R.T + np.array([self.x_m, self.y_m, self.z_base_m])


def _dome_fraction(shape_code: int, un: np.ndarray, vn: np.ndarray) -> np.ndarray:
    """Height of a rock model over its visible height, in normalised footprint coordinates; NaN outside.

    ``un = u / (L/2)``, ``vn = v / (W/2)`` in the rock's own frame. Semi-ellipsoid / hemispheroid: ``sqrt(1 -
    r^2)``; cone: ``1 - r``; tetrahedron: one minus the gauge of the base triangle about its centroid (a
    pyramid with planar faces).
    """
    ellipsoidal = shape_code in (_SHAPE_CODES["hemispheroid"], _SHAPE_CODES["semi_ellipsoid"])
    if ellipsoidal:
        clearance = 1.0 - (un * un + vn * vn)
    elif shape_code == _SHAPE_CODES["cone"]:
        clearance = 1.0 - np.hypot(un, vn)
    else:
        clearance = 1.0 - np.maximum(np.maximum(-1.5 * un, 0.75 * (un + 2.0 * vn)), 0.75 * (un - 2.0 * vn))
    inside = clearance >= -_OUTLINE_TOLERANCE
    clearance = np.maximum(clearance, 0.0)
    frac = np.sqrt(clearance) if ellipsoidal else clearance
    return np.where(inside, frac, np.nan)


@dataclass(frozen=True)
class _RockTable:
    """Rock parameters as arrays, for evaluating many rocks against many points at once."""

    xy: np.ndarray  # (n, 2)
    z_base: np.ndarray
    cos_yaw: np.ndarray
    sin_yaw: np.ndarray
    half_length: np.ndarray
    half_width: np.ndarray
    height: np.ndarray
    code: np.ndarray
    radius: np.ndarray

    @classmethod
    def of(cls, rocks: list[Rock]) -> _RockTable:
        def col(f: str) -> np.ndarray:
            return np.array([getattr(r, f) for r in rocks], dtype=np.float64)

        yaw = col("yaw_rad")
        return cls(
            xy=np.column_stack([col("x_m"), col("y_m")]),
            z_base=col("z_base_m"),
            cos_yaw=np.cos(yaw),
            sin_yaw=np.sin(yaw),
            half_length=0.5 * col("length_m"),
            half_width=0.5 * col("width_m"),
            height=col("height_m"),
            code=np.array([_SHAPE_CODES[r.shape] for r in rocks], dtype=np.intp),
            radius=np.array([r.footprint_radius_m for r in rocks]),
        )

    def top_z(self, rock_idx: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        """Top-surface z of rock ``rock_idx[k]`` at point ``(px[k], py[k])``, NaN outside its footprint."""
        dx, dy = px - self.xy[rock_idx, 0], py - self.xy[rock_idx, 1]
        c, s = self.cos_yaw[rock_idx], self.sin_yaw[rock_idx]
        un = (c * dx + s * dy) / self.half_length[rock_idx]
        vn = (-s * dx + c * dy) / self.half_width[rock_idx]
        frac = np.full(len(rock_idx), np.nan)
        codes = self.code[rock_idx]
        for code in np.unique(codes):
            sel = codes == code
            frac[sel] = _dome_fraction(int(code), un[sel], vn[sel])
        return self.z_base[rock_idx] + self.height[rock_idx] * frac


# ------------------------------------------------------------------------------------------------ terrain


def bilinear_sample(grid: np.ndarray, cell_size_m: float, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of a centred grid (hfield convention) at world points; clamps at the edges."""
    nrow, ncol = grid.shape
    fj = np.clip((x_m + 0.5 * (ncol - 1) * cell_size_m) / cell_size_m, 0.0, ncol - 1.0)
    fi = np.clip((y_m + 0.5 * (nrow - 1) * cell_size_m) / cell_size_m, 0.0, nrow - 1.0)
    j0 = np.minimum(fj.astype(np.intp), ncol - 2)
    i0 = np.minimum(fi.astype(np.intp), nrow - 2)
    tx, ty = fj - j0, fi - i0
    lower = grid[i0, j0] * (1.0 - tx) + grid[i0, j0 + 1] * tx
    upper = grid[i0 + 1, j0] * (1.0 - tx) + grid[i0 + 1, j0 + 1] * tx
    return lower * (1.0 - ty) + upper * ty


def _as_xy(x_m: np.ndarray | float, y_m: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.broadcast_arrays(np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64))
    return x, y


def _scalar_or_array(a: np.ndarray) -> np.ndarray:
    return a[()] if a.ndim == 0 else a


_MATERIAL_RGBA = {
    Material.SAND: (194, 140, 102, 255),
    Material.BEDROCK: (150, 118, 96, 255),
    Material.MIXED: (172, 128, 98, 255),
    Material.DRIFT: (206, 152, 112, 255),
}


@dataclass(eq=False)
class Terrain:
    """A synthesised (or hand-made) terrain patch: heights, materials and rocks on a centred grid.

    See the module docstring for the grid convention. ``recipe`` is ``None`` for a terrain built directly from
    arrays (:meth:`from_heights`). Query methods are vectorised: pass arrays of x and y (broadcast together)
    and get arrays back; scalars give scalars.
    """

    heights_m: np.ndarray
    cell_size_m: float
    materials: np.ndarray
    rocks: list[Rock] = field(default_factory=list)
    seed: int = 0
    recipe: TerrainRecipe | None = None

    def __post_init__(self) -> None:
        heights = np.asarray(self.heights_m, dtype=np.float64)
        if heights.ndim != 2 or min(heights.shape) < 2:
            raise InvalidTerrainError(
                f"heights_m must be a 2-D array of at least 2 x 2, got shape {heights.shape}"
            )
        if not np.all(np.isfinite(heights)):
            raise InvalidTerrainError("heights_m contains NaN or inf; fill holes before building a Terrain")
        if not (math.isfinite(self.cell_size_m) and self.cell_size_m > 0.0):
            raise InvalidTerrainError(f"cell_size_m must be a positive number, got {self.cell_size_m}")
        materials = np.asarray(self.materials)
        if materials.shape != heights.shape:
            raise InvalidTerrainError(
                f"materials shape {materials.shape} differs from heights_m shape {heights.shape}"
            )
        if not np.issubdtype(materials.dtype, np.integer) or not np.isin(materials, list(Material)).all():
            raise InvalidTerrainError(f"materials must hold Material codes {[int(m) for m in Material]}")
        self.heights_m = heights
        self.materials = materials.astype(np.uint8, copy=False)
        self.cell_size_m = float(self.cell_size_m)
        self.rocks = list(self.rocks)
        self.seed = int(self.seed)

    @classmethod
    def from_heights(
        cls, heights_m: np.ndarray, cell_size_m: float, material: Material = Material.SAND
    ) -> Terrain:
        """A rock-free terrain of one material from a height grid (hfield convention)."""
        heights = np.asarray(heights_m, dtype=np.float64)
        return cls(heights, cell_size_m, np.full(heights.shape, int(material), dtype=np.uint8))

    # -- grid ------------------------------------------------------------------------------------------------

    @property
    def nrow(self) -> int:
        return int(self.heights_m.shape[0])

    @property
    def ncol(self) -> int:
        return int(self.heights_m.shape[1])

    @property
    def half_x_m(self) -> float:
        return 0.5 * (self.ncol - 1) * self.cell_size_m

    @property
    def half_y_m(self) -> float:
        return 0.5 * (self.nrow - 1) * self.cell_size_m

    @property
    def origin_xy_m(self) -> tuple[float, float]:
        """World point at the grid's centre: the origin here; a streamed window sits elsewhere (terrains.stream)."""
        return (0.0, 0.0)

    @property
    def xs_m(self) -> np.ndarray:
        """x of each column, ``(ncol,)``."""
        return -self.half_x_m + np.arange(self.ncol) * self.cell_size_m

    @property
    def ys_m(self) -> np.ndarray:
        """y of each row, ``(nrow,)``."""
        return -self.half_y_m + np.arange(self.nrow) * self.cell_size_m

    # -- queries ---------------------------------------------------------------------------------------------

    def height_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        """Ground height (no rocks) by bilinear interpolation; points outside the patch take the edge
        value."""
        x, y = _as_xy(x_m, y_m)
        return _scalar_or_array(bilinear_sample(self.heights_m, self.cell_size_m, x, y))

    def normal_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        """Unit upward ground normal, ``(..., 3)``, from central differences one cell wide (clamped
        in-patch)."""
        x, y = _as_xy(x_m, y_m)
        x = np.clip(x, -self.half_x_m, self.half_x_m)
        y = np.clip(y, -self.half_y_m, self.half_y_m)
        h = self.cell_size_m
        x_lo, x_hi = np.maximum(x - h, -self.half_x_m), np.minimum(x + h, self.half_x_m)
        y_lo, y_hi = np.maximum(y - h, -self.half_y_m), np.minimum(y + h, self.half_y_m)
        g, c = self.heights_m, self.cell_size_m
        dz_dx = (bilinear_sample(g, c, x_hi, y) - bilinear_sample(g, c, x_lo, y)) / (x_hi - x_lo)
        dz_dy = (bilinear_sample(g, c, x, y_hi) - bilinear_sample(g, c, x, y_lo)) / (y_hi - y_lo)
        n = np.stack([-dz_dx, -dz_dy, np.ones_like(dz_dx)], axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def slope_deg_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        """Ground tilt from horizontal, degrees."""
        nz = self.normal_at(x_m, y_m)[..., 2]
        return _scalar_or_array(np.degrees(np.arccos(np.clip(nz, -1.0, 1.0))))

    def material_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        """Material code (``uint8``, compare with :class:`Material`) of the nearest cell; clamps at the
        edges."""
        x, y = _as_xy(x_m, y_m)
        j = np.clip(np.rint((x + self.half_x_m) / self.cell_size_m), 0, self.ncol - 1).astype(np.intp)
        i = np.clip(np.rint((y + self.half_y_m) / self.cell_size_m), 0, self.nrow - 1).astype(np.intp)
        return _scalar_or_array(self.materials[i, j])

    def height_with_rocks_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        """Highest surface at ``(x, y)``: the ground or the top of any rock there (analytic per rock shape).

        This is the ground truth a ray cast straight down would hit; at a rock's centre it is
        ``z_base_m + height_m``.
        """
        x, y = _as_xy(x_m, y_m)
        out = bilinear_sample(self.heights_m, self.cell_size_m, x, y).ravel()
        analytic = [r for r in self.rocks if r.shape in _SHAPE_CODES]
        if analytic and x.size:
            table = _RockTable.of(analytic)
            px, py = x.ravel(), y.ravel()
            rock_idx, pt_idx = _candidate_pairs(table, px, py)
            if rock_idx.size:
                z = table.top_z(rock_idx, px[pt_idx], py[pt_idx])
                inside = ~np.isnan(z)
                np.maximum.at(out, pt_idx[inside], z[inside])
        for rock in (r for r in self.rocks if r.shape not in _SHAPE_CODES):  # irregular rocks (rock_shapes.py)
            px, py = x.ravel(), y.ravel()
            near = np.flatnonzero(np.hypot(px - rock.x_m, py - rock.y_m) <= rock.footprint_radius_m)
            if near.size:
                z = np.atleast_1d(rock.top_z_at(px[near], py[near]))
                inside = ~np.isnan(z)
                np.maximum.at(out, near[inside], z[inside])
        return _scalar_or_array(out.reshape(x.shape))

    # -- output ----------------------------------------------------------------------------------------------

    def to_mesh(self, step: int = 1, colour_by_material: bool = True) -> trimesh.Trimesh:
        """Triangle mesh of the heightfield (no rocks), every ``step`` cells (the last row/column always
        kept)."""
        if step < 1:
            raise InvalidTerrainError(f"to_mesh step must be >= 1, got {step}")
        rows = np.unique(np.r_[np.arange(0, self.nrow, step), self.nrow - 1])
        cols = np.unique(np.r_[np.arange(0, self.ncol, step), self.ncol - 1])
        gx, gy = np.meshgrid(self.xs_m[cols], self.ys_m[rows])
        vertices = np.column_stack([gx.ravel(), gy.ravel(), self.heights_m[np.ix_(rows, cols)].ravel()])
        nr, nc = len(rows), len(cols)
        v00 = (np.arange(nr - 1)[:, None] * nc + np.arange(nc - 1)[None, :]).ravel()
        v01, v10, v11 = v00 + 1, v00 + nc, v00 + nc + 1
        faces = np.concatenate([np.column_stack([v00, v01, v11]), np.column_stack([v00, v11, v10])])
        colours = None
        if colour_by_material:
            palette = np.zeros((max(_MATERIAL_RGBA) + 1, 4), dtype=np.uint8)
            for m, rgba in _MATERIAL_RGBA.items():
                palette[m] = rgba
            colours = palette[self.materials[np.ix_(rows, cols)].ravel()]
        return trimesh.Trimesh(vertices=vertices, faces=faces, vertex_colors=colours, process=False)

    def save(self, path: str | Path) -> Path:
        """Write a single ``.npz``: the arrays plus a JSON header (recipe, seed, cell size, rocks). Exact."""
        path = Path(path)
        meta = {
            "format": FILE_FORMAT,
            "version": FILE_VERSION,
            "seed": self.seed,
            "cell_size_m": self.cell_size_m,
            "recipe": None if self.recipe is None else self.recipe.model_dump(mode="json"),
            "rocks": [dataclasses.asdict(r) for r in self.rocks],
        }
        with path.open("wb") as f:
            np.savez_compressed(
                f, heights_m=self.heights_m, materials=self.materials, meta=np.array(json.dumps(meta))
            )
        return path

    @classmethod
    def load(cls, path: str | Path) -> Terrain:
        """Read a file written by :meth:`save`."""
        with np.load(Path(path), allow_pickle=False) as data:
            missing = {"heights_m", "materials", "meta"} - set(data.files)
            if missing:
                raise TerrainFileError(
                    f"{path}: not a terrain file (missing {sorted(missing)}); write it with Terrain.save"
                )
            meta = json.loads(str(data["meta"]))
            heights, materials = data["heights_m"], data["materials"]
        if meta.get("format") != FILE_FORMAT or meta.get("version") != FILE_VERSION:
            raise TerrainFileError(
                f"{path}: format {meta.get('format')!r} version {meta.get('version')!r}; this code reads "
                f"{FILE_FORMAT!r} version {FILE_VERSION} (re-synthesise the terrain from its recipe and seed)"
            )
        recipe = None if meta["recipe"] is None else TerrainRecipe.model_validate(meta["recipe"])
        return cls(
            heights_m=heights,
            cell_size_m=meta["cell_size_m"],
            materials=materials,
            rocks=[_rock_from_fields(r, path) for r in meta["rocks"]],
            seed=meta["seed"],
            recipe=recipe,
        )


def _rock_from_fields(fields: dict, path: object) -> Rock:
    """A saved rock: a :class:`Rock` or the subclass whose fields it has (e.g. terrains.rock_shapes.IrregularRock)."""
    for kind in (Rock, *Rock.__subclasses__()):
        if set(fields) == {f.name for f in dataclasses.fields(kind)}:
            return kind(**fields)
    raise TerrainFileError(f"{path}: rock fields {sorted(fields)} match no rock kind; re-synthesise the terrain")


def _candidate_pairs(table: _RockTable, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rock index, point index) pairs whose distance is within the rock's footprint radius."""
    n_rocks, n_pts = len(table.radius), len(px)
    if n_rocks * n_pts <= 200_000:
        d = np.hypot(px[None, :] - table.xy[:, 0:1], py[None, :] - table.xy[:, 1:2])
        rock_idx, pt_idx = np.nonzero(d <= table.radius[:, None])
        return rock_idx, pt_idx
    rock_tree = cKDTree(table.xy)
    pt_tree = cKDTree(np.column_stack([px, py]))
    pairs = rock_tree.sparse_distance_matrix(pt_tree, float(table.radius.max()), output_type="ndarray")
    rock_idx, pt_idx = pairs["i"].astype(np.intp), pairs["j"].astype(np.intp)
    keep = pairs["v"] <= table.radius[rock_idx]
    return rock_idx[keep], pt_idx[keep]
