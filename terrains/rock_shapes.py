"""Irregular rocks: shapes outside the four analytic models the rock modeller fits.

The generator's analytic rocks (hemispheroid, semi-ellipsoid, cone, tetrahedron) are exactly the models of
Li et al.'s rock modeller (``nav.rocks``), so model accuracy measured on them is in-class only. Real rocks are not:
Golombek & Rapp (1997) and the MER rock counts describe angular, sub-rounded and tabular clasts. Three irregular
forms, each a convex polyhedron drawn per rock from its own seed, inside the footprint ellipse of the analytic rock
it replaces (same place, length, width and yaw, so placement is unchanged):

* ``irregular_hull``: a noise-displaced dome, the convex hull of points on the semi-ellipsoid pulled inwards by
  up to 35 % (lumpy, sub-rounded);
* ``angular_block``: a jittered box inscribed in the footprint with an uneven, tilted top (angular);
* ``slab``: a tabular rock, 60 % of the drawn height, a 5-8 sided outline and a flat tilted top.

:class:`IrregularRock` is a :class:`terrains.Rock` whose geometry comes from those vertices; ``rock_class``
("analytic" | "irregular") is for evaluation only (truth side). :func:`make_irregular` is the generator's hook.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
import trimesh
from scipy.spatial import ConvexHull

from terrains.errors import InvalidRockError
from terrains.terrain import Rock

IrregularForm = Literal["irregular_hull", "angular_block", "slab"]
IRREGULAR_FORMS: tuple[IrregularForm, ...] = get_args(IrregularForm)
SLAB_HEIGHT_FRACTION = 0.6  # a slab is this fraction of the analytic rock's height (tabular: H/D ~ 0.25)
HULL_DENT_MAX = 0.35  # an irregular hull's surface points are pulled in by up to this fraction of the radius
_HULL_POINTS = 48
_BASE_POINTS = 16


def rock_class(rock: Rock) -> Literal["analytic", "irregular"]:
    """``"irregular"`` for an :class:`IrregularRock`, else ``"analytic"`` (for evaluation, truth side)."""
    return "irregular" if isinstance(rock, IrregularRock) else "analytic"


@dataclass(frozen=True)
class IrregularRock(Rock):
    """A convex polyhedral rock; ``shape`` is one of :data:`IRREGULAR_FORMS`, ``form_seed`` draws its vertices."""

    form_seed: int = 0

    def __post_init__(self) -> None:
        if self.shape not in IRREGULAR_FORMS:
            raise InvalidRockError(f"unknown irregular rock form {self.shape!r}; use one of {IRREGULAR_FORMS}")
        values = (self.x_m, self.y_m, self.z_base_m, self.length_m, self.width_m, self.height_m, self.yaw_rad)
        if not all(math.isfinite(v) for v in (*values, self.buried_m)):
            raise InvalidRockError(f"rock {self.name!r} has a non-finite coordinate or size: {self}")
        if min(self.length_m, self.width_m, self.height_m) <= 0.0 or self.buried_m < 0.0:
            raise InvalidRockError(f"rock {self.name!r}: sizes must be > 0 and buried_m >= 0 ({self})")

    # -- geometry (local frame: origin at the base centre, x along the rock's length) -----------------------

    def _local(self) -> tuple[np.ndarray, np.ndarray]:
        """(visible vertices (n, 3), base outline at ground level (k, 2)), cached per rock geometry."""
        return _vertices(self.shape, self.length_m, self.width_m, self.height_m, self.form_seed)

    @property
    def footprint_area_m2(self) -> float:
        return float(ConvexHull(self._local()[1]).volume)

    @property
    def footprint_radius_m(self) -> float:
        verts, base = self._local()
        return float(max(np.hypot(verts[:, 0], verts[:, 1]).max(), np.hypot(base[:, 0], base[:, 1]).max()))

    @property
    def visible_volume_m3(self) -> float:
        return float(ConvexHull(self._local()[0]).volume)

    def footprint_xy_m(self, n: int = 16) -> np.ndarray:
        base = self._local()[1]
        return self._to_world(np.column_stack([base, np.zeros(len(base))]))[:, :2]

    def mesh(self) -> trimesh.Trimesh:
        """Watertight convex mesh of the whole rock (visible part and buried skirt) in world coordinates."""
        verts, base = self._local()
        pts = verts
        if self.buried_m > 1e-9:
            pts = np.vstack([verts, np.column_stack([base, np.full(len(base), -self.buried_m)])])
        return trimesh.convex.convex_hull(self._to_world(pts))

    def top_z_at(self, x_m: np.ndarray | float, y_m: np.ndarray | float) -> np.ndarray:
        """World height of the rock's top surface at ``(x, y)``; NaN outside its footprint. Vectorised."""
        x, y = np.broadcast_arrays(np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64))
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        dx, dy = x - self.x_m, y - self.y_m
        u, v = c * dx + s * dy, -s * dx + c * dy
        top, bottom = _planes(self.shape, self.length_m, self.width_m, self.height_m, self.form_seed)
        pts = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=1)
        z_top = (pts @ top.T).min(axis=1) if len(top) else np.full(u.size, np.nan)
        z_bottom = (pts @ bottom.T).max(axis=1) if len(bottom) else np.zeros(u.size)
        z = np.where((z_top >= z_bottom - 1e-9) & (z_top >= 0.0), z_top, np.nan).reshape(u.shape)
        out = self.z_base_m + z
        return out if out.ndim else float(out)  # type: ignore[return-value]


@functools.lru_cache(maxsize=4096)
def _vertices(form: str, length_m: float, width_m: float, height_m: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Visible vertices (z >= 0, the highest at ``height_m``) and ground outline, inside the footprint ellipse."""
    rng = np.random.default_rng(seed)
    a, b, h = 0.5 * length_m, 0.5 * width_m, height_m
    if form == "irregular_hull":
        az = rng.uniform(0.0, 2.0 * np.pi, _HULL_POINTS)
        el = np.arcsin(rng.uniform(0.05, 0.95, _HULL_POINTS))  # uniform in height on the sphere
        r = 1.0 - HULL_DENT_MAX * rng.uniform(0.0, 1.0, _HULL_POINTS)
        dome = np.column_stack([a * r * np.cos(el) * np.cos(az), b * r * np.cos(el) * np.sin(az), h * r * np.sin(el)])
        base_az = np.sort(rng.uniform(0.0, 2.0 * np.pi, _BASE_POINTS))
        base_r = rng.uniform(0.75, 1.0, _BASE_POINTS)
        base = np.column_stack([a * base_r * np.cos(base_az), b * base_r * np.sin(base_az)])
        apex = np.array([[a * rng.uniform(-0.2, 0.2), b * rng.uniform(-0.2, 0.2), h]])
        verts = np.vstack([dome, np.column_stack([base, np.zeros(len(base))]), apex])
    elif form == "angular_block":
        corners_az = np.deg2rad(45.0 + 90.0 * np.arange(4) + rng.uniform(-15.0, 15.0, 4))
        base = np.column_stack([a * np.cos(corners_az), b * np.sin(corners_az)])
        top_scale = rng.uniform(0.7, 0.95, 4)[:, None]
        top_z = h * rng.uniform(0.65, 1.0, 4)
        top_z[rng.integers(4)] = h
        top = np.column_stack([base * top_scale, top_z])
        verts = np.vstack([np.column_stack([base, np.zeros(4)]), top])
    elif form == "slab":
        n = int(rng.integers(5, 9))
        az = np.sort(rng.uniform(0.0, 2.0 * np.pi, n))
        base = np.column_stack([a * rng.uniform(0.85, 1.0, n) * np.cos(az), b * rng.uniform(0.85, 1.0, n) * np.sin(az)])
        tilt = rng.uniform(-0.15, 0.15, 2) * h  # a flat, slightly tilted top
        top_xy = base * rng.uniform(0.8, 0.92)
        top_z = h + tilt[0] * top_xy[:, 0] / a + tilt[1] * top_xy[:, 1] / b
        top_z = top_z - (top_z.max() - h)
        verts = np.vstack([np.column_stack([base, np.zeros(n)]), np.column_stack([top_xy, top_z])])
    else:
        raise InvalidRockError(f"unknown irregular rock form {form!r}; use one of {IRREGULAR_FORMS}")
    verts[:, 2] = np.clip(verts[:, 2], 0.0, h)
    return verts, ConvexHull(base).points[ConvexHull(base).vertices]


@functools.lru_cache(maxsize=4096)
def _planes(form: str, length_m: float, width_m: float, height_m: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The visible hull's faces as ``z = p . (u, v, 1)``: upward faces (top surface = their minimum) and
    downward ones (bottom = their maximum; the base at z = 0 is one)."""
    verts = _vertices(form, length_m, width_m, height_m, seed)[0]
    eq = ConvexHull(verts).equations  # n . p + d = 0, n outward
    n, d = eq[:, :3], eq[:, 3]
    up, down = n[:, 2] > 1e-9, n[:, 2] < -1e-9

    def as_z(sel: np.ndarray) -> np.ndarray:
        return np.column_stack([-n[sel, 0] / n[sel, 2], -n[sel, 1] / n[sel, 2], -d[sel] / n[sel, 2]])

    return as_z(up), as_z(down)


def make_irregular(rocks: list[Rock], fraction: float, forms: tuple[str, ...], rng: np.random.Generator) -> list[Rock]:
    """The generator's hook: each rock becomes an irregular one of a random form with probability ``fraction``
    (same centre, footprint extents, yaw and buried depth; a slab is flattened to ``SLAB_HEIGHT_FRACTION``).
    ``fraction = 0`` returns the rocks unchanged without drawing from ``rng``."""
    if fraction <= 0.0 or not rocks:
        return rocks
    out: list[Rock] = []
    for rock in rocks:
        pick, form_index, seed = rng.random(), int(rng.integers(len(forms))), int(rng.integers(2**31))
        if pick >= fraction:
            out.append(rock)
            continue
        form = forms[form_index]
        height = rock.height_m * (SLAB_HEIGHT_FRACTION if form == "slab" else 1.0)
        out.append(
            IrregularRock(
                **{k: getattr(rock, k) for k in ("x_m", "y_m", "z_base_m", "length_m", "width_m", "yaw_rad", "name")},
                height_m=height,
                buried_m=rock.buried_m,
                shape=form,  # type: ignore[arg-type]
                form_seed=seed,
            )
        )
    return out
