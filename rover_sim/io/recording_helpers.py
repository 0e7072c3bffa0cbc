"""Small helpers of :class:`rover_sim.io.recording.RerunRecorder`: the rover visual, colours, quaternion order,
terrain decimation, trajectory bookkeeping."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr

if TYPE_CHECKING:
    from terrains import Terrain

TERRAIN_MAX_TRIANGLES = 200_000  # finer terrain grids are decimated (Terrain.to_mesh(step=...)) below this

_TRAJECTORY_RGB = {"truth": (245, 245, 245), "dead_reckoning": (255, 150, 0), "vo": (0, 170, 255)}
_OTHER_RGB = ((200, 80, 255), (80, 220, 120), (255, 80, 120), (255, 230, 60))

# Approximate MER rover visual in the rover frame (from models/mer/rover.xml: web, solar deck, mast pole, wheels
# of radius 0.125 m and width 0.16 m; rover origin 0.525 m above flat ground).
_BODY_CENTERS = [(0.0, 0.0, 0.03), (-0.02, 0.0, 0.175), (-0.25, 0.85, 0.17), (-0.25, -0.85, 0.17), (0.35, 0.2, 0.55)]
_BODY_HALF_SIZES = [(0.55, 0.35, 0.13), (0.80, 0.55, 0.012), (0.45, 0.30, 0.01), (0.45, 0.30, 0.01), (0.03, 0.03, 0.36)]
_BODY_RGBA = [(217, 209, 191, 255), (31, 36, 71, 255), (31, 36, 71, 255), (31, 36, 71, 255), (200, 200, 200, 255)]
_WHEEL_RADIUS_M = 0.125
_WHEEL_WIDTH_M = 0.16
_WHEEL_CENTERS = [(x, y, -0.525 + _WHEEL_RADIUS_M) for x in (0.55, 0.0, -0.55) for y in (0.55, -0.55)]


def rover_visual() -> tuple[rr.Boxes3D, rr.Cylinders3D]:
    """The rover's static visual, in the rover frame: body boxes and six wheel cylinders."""
    q = math.sqrt(0.5)
    return (
        rr.Boxes3D(
            centers=_BODY_CENTERS,
            half_sizes=_BODY_HALF_SIZES,
            colors=_BODY_RGBA,
            fill_mode=rr.components.FillMode.Solid,
        ),
        rr.Cylinders3D(
            centers=_WHEEL_CENTERS,
            lengths=[_WHEEL_WIDTH_M] * 6,
            radii=[_WHEEL_RADIUS_M] * 6,
            quaternions=[rr.Quaternion(xyzw=[q, 0.0, 0.0, q])] * 6,  # cylinder axis z -> rover y
            colors=[(60, 60, 60, 255)] * 6,
            fill_mode=rr.components.FillMode.Solid,
        ),
    )


def ramp_red_green(x: np.ndarray) -> np.ndarray:
    """``(N, 3)`` uint8 colours: 0 red -> 0.5 yellow -> 1 green (x clipped to [0, 1])."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)[:, None]
    red, yellow, green = np.array([215, 40, 30.0]), np.array([235, 200, 40.0]), np.array([40, 185, 60.0])
    lo = red + (yellow - red) * (2.0 * x)
    hi = yellow + (green - yellow) * (2.0 * x - 1.0)
    return np.where(x < 0.5, lo, hi).round().astype(np.uint8)


def xyzw(quat_wxyz: np.ndarray) -> np.ndarray:
    q = np.asarray(quat_wxyz, dtype=np.float64)
    return np.array([q[1], q[2], q[3], q[0]])


def colour_of(name: str) -> tuple[int, int, int]:
    if name in _TRAJECTORY_RGB:
        return _TRAJECTORY_RGB[name]
    return _OTHER_RGB[sum(map(ord, name)) % len(_OTHER_RGB)]


def terrain_mesh_step(nrow: int, ncol: int, max_triangles: int = TERRAIN_MAX_TRIANGLES) -> int:
    """Smallest ``Terrain.to_mesh`` step that keeps the mesh under ``max_triangles`` triangles."""
    step = 1
    while 2 * math.ceil((nrow - 1) / step) * math.ceil((ncol - 1) / step) > max_triangles:
        step += 1
    return step


@dataclass
class PolylineState:
    """Incremental bookkeeping of one trajectory (see the :mod:`rover_sim.io.recording` docstring)."""

    n_in: int = 0  # input points consumed
    last_in: np.ndarray | None = None  # the last consumed input point, to detect a rewritten history
    block: int = 0  # index of the open block
    kept: list[np.ndarray] = field(default_factory=list)  # vertices of the open block


ROCK_RGBA = (120, 104, 92, 255)


def ground_mesh(terrain: Terrain, step: int, offset_xy_m: tuple[float, float] | None = None) -> rr.Mesh3D:
    """The heightfield every ``step`` cells, coloured by material; moved by ``offset_xy_m`` (a tile of a grid)."""
    mesh = terrain.to_mesh(step=step, colour_by_material=True)
    vertices = np.asarray(mesh.vertices)
    if offset_xy_m is not None:
        vertices = vertices + np.array([offset_xy_m[0], offset_xy_m[1], 0.0])
    return rr.Mesh3D(
        vertex_positions=np.asarray(vertices, dtype=np.float32),
        triangle_indices=np.asarray(mesh.faces, dtype=np.uint32),
        vertex_normals=np.asarray(mesh.vertex_normals, dtype=np.float32),
        vertex_colors=np.asarray(mesh.visual.vertex_colors, dtype=np.uint8),
    )


def rocks_mesh(rocks: list) -> rr.Mesh3D:
    """All ``rocks`` as one mesh (their analytic shapes, world frame)."""
    meshes = [rock.mesh() for rock in rocks]
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return rr.Mesh3D(
        vertex_positions=np.concatenate([np.asarray(m.vertices) for m in meshes]).astype(np.float32),
        triangle_indices=np.concatenate([np.asarray(m.faces) + o for m, o in zip(meshes, offsets, strict=True)]).astype(
            np.uint32
        ),
        albedo_factor=ROCK_RGBA,
    )


def tile_rocks(rocks: list) -> rr.Ellipsoids3D | rr.Mesh3D:
    """A streamed tile's rocks: ellipsoids (exact for its hemispheroids and semi-ellipsoids, about 40 bytes a
    rock, centred on the base with the lower half under the ground), else their meshes."""
    if any(r.shape not in ("hemispheroid", "semi_ellipsoid") for r in rocks):
        return rocks_mesh(rocks)
    half = np.array([[0.5 * r.length_m, 0.5 * r.width_m, r.height_m] for r in rocks], dtype=np.float32)
    yaw = np.array([0.5 * r.yaw_rad for r in rocks])
    quat_xyzw = np.stack([np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw), np.cos(yaw)], axis=1)
    return rr.Ellipsoids3D(
        centers=np.array([[r.x_m, r.y_m, r.z_base_m] for r in rocks], dtype=np.float32),
        half_sizes=half,
        quaternions=quat_xyzw.astype(np.float32),
        colors=[ROCK_RGBA],
        fill_mode="solid",
    )
