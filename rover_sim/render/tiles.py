"""Render-only terrain tiles: the heightfield cut into square tiles, each as a chain of level-of-detail meshes.

:class:`rover_sim.render.render_world.RenderWorld` draws them in place of the physics hfield (see the renderer's
module docstring and :class:`TerrainTiles`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

if TYPE_CHECKING:
    from terrains import Terrain

TILE_PREFIX = "terrain_tile_"
TILE_MATERIAL = "terrain_tile"
GROUP_SHOWN = 1  # render-only geoms that are drawn
GROUP_HIDDEN = 5  # render-only geoms culled for this frame; also the physics hfield (drawn as tiles instead)


@dataclass(frozen=True)
class TerrainTiles:
    """Render-only terrain: square tiles of the heightfield, each as a chain of level-of-detail meshes.

    Level ``L`` keeps every ``2**L``-th grid row and column of its tile (the tile's last row/column always), so
    it draws the exact hfield surface at ``L = 0`` and a coarser triangulation above; ``error_m[t, L]`` is the
    largest vertical distance between the hfield and level ``L`` over tile ``t`` (``inf`` where the level does
    not exist). A skirt hanging below each tile edge (as deep as this tile's and its neighbours' largest level
    errors) hides the hairline cracks between neighbouring tiles drawn at different levels.
    """

    geom_names: np.ndarray  # (N, levels) object array of geom names, "" where the level does not exist
    boxes: np.ndarray  # (N, 2, 3) world AABB (min, max) of each tile, skirt included
    error_m: np.ndarray  # (N, levels) non-decreasing in L
    centres: np.ndarray  # (N, 3) a point of each tile's mean plane (its centre)
    normals: np.ndarray  # (N, 3) unit upward mean normal of each tile

    def geom_ids(self, model: mujoco.MjModel) -> np.ndarray:
        """(N, levels) geom ids in ``model``, -1 where the level does not exist."""
        return np.vectorize(lambda n: model.geom(n).id if n else -1, otypes=[np.int32])(self.geom_names)

    def choose_levels(self, allowed_error_m: np.ndarray) -> np.ndarray:
        """Coarsest level per tile whose height error is at most ``allowed_error_m`` (per tile)."""
        ok = self.error_m <= allowed_error_m[:, None]
        return np.maximum(ok.sum(axis=1) - 1, 0)  # error is non-decreasing in L; level 0 is exact


def _level_indices(lo: int, hi: int, step: int) -> np.ndarray:
    return np.unique(np.r_[np.arange(lo, hi, step), hi])


def _decimation_error(h: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> float:
    """Max |h - surface through h[rows][:, cols]| over the tile grid ``h``, with MuJoCo's (i,j)-(i+1,j+1) split."""
    ri = np.clip(np.searchsorted(rows, np.arange(h.shape[0]), side="right") - 1, 0, len(rows) - 2)
    ci = np.clip(np.searchsorted(cols, np.arange(h.shape[1]), side="right") - 1, 0, len(cols) - 2)
    fi = ((np.arange(h.shape[0]) - rows[ri]) / (rows[ri + 1] - rows[ri]))[:, None]
    fj = ((np.arange(h.shape[1]) - cols[ci]) / (cols[ci + 1] - cols[ci]))[None, :]
    R, C = rows[ri][:, None], cols[ci][None, :]
    R1, C1 = rows[ri + 1][:, None], cols[ci + 1][None, :]
    h00, h01, h10, h11 = h[R, C], h[R, C1], h[R1, C], h[R1, C1]
    upper = h00 + fj * (h01 - h00) + fi * (h11 - h01)  # triangle (i,j), (i,j+1), (i+1,j+1)
    lower = h00 + fi * (h10 - h00) + fj * (h11 - h10)  # triangle (i,j), (i+1,j+1), (i+1,j)
    return float(np.abs(h - np.where(fj >= fi, upper, lower)).max())


def _tile_mesh(
    terrain: Terrain, normals: np.ndarray, rows: np.ndarray, cols: np.ndarray, skirt_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Vertices, faces, normals and texcoords of one tile level, plus a two-sided skirt along its border."""
    h = terrain.heights_m
    ii, jj = np.meshgrid(rows, cols, indexing="ij")
    verts = np.stack([terrain.xs_m[jj], terrain.ys_m[ii], h[ii, jj]], axis=-1).reshape(-1, 3)
    norms = normals[ii, jj].reshape(-1, 3)
    k = np.arange(ii.size).reshape(ii.shape)
    a, b, c, d = k[:-1, :-1].ravel(), k[:-1, 1:].ravel(), k[1:, 1:].ravel(), k[1:, :-1].ravel()
    faces = [np.stack([a, b, c], 1), np.stack([a, c, d], 1)]  # counter-clockwise seen from above
    ring = np.r_[k[0, :-1], k[:-1, -1], k[-1, :0:-1], k[:0:-1, 0], k[0, 0]]  # closed loop along the border
    low = len(verts) + np.arange(len(ring))
    verts = np.vstack([verts, verts[ring] - [0.0, 0.0, skirt_m]])
    norms = np.vstack([norms, norms[ring]])  # skirts shade like the ground they patch
    top0, top1, low0, low1 = ring[:-1], ring[1:], low[:-1], low[1:]
    skirt = np.concatenate([np.stack([top0, low0, low1], 1), np.stack([top0, low1, top1], 1)])
    faces += [skirt, skirt[:, ::-1]]  # both windings: the skirt is seen from either side
    ox, oy = terrain.origin_xy_m  # a streamed window's centre (0, 0 otherwise)
    u = (verts[:, 0] - ox + terrain.half_x_m) / (2.0 * terrain.half_x_m)
    v = (terrain.half_y_m - verts[:, 1] + oy) / (2.0 * terrain.half_y_m)  # first texture row = north (world.py)
    return verts, np.concatenate(faces), norms, np.stack([u, v], axis=-1)


@dataclass(frozen=True)
class TileMesh:
    """One level of one tile: world-frame vertices, faces, normals and texture coordinates (skirt included)."""

    name: str
    verts: np.ndarray  # (V, 3) world metres
    faces: np.ndarray  # (F, 3) vertex indices
    normals: np.ndarray  # (V, 3) unit
    uv: np.ndarray  # (V, 2) into the window's terrain texture


def tile_meshes(terrain: Terrain, tile_m: float, max_tiles: int) -> tuple[TerrainTiles, list[TileMesh]]:
    """The render-only terrain of ``terrain``: tile bookkeeping and every tile level's mesh (see
    :func:`add_terrain_tiles`). The layout (tiles, levels, vertex and face counts) depends only on the grid's
    shape and cell, so every window of a streamed site has the same one (:func:`write_tile_meshes`)."""
    h = terrain.heights_m
    nrow, ncol = h.shape
    gy, gx = np.gradient(h, terrain.cell_size_m)
    normals = np.stack([-gx, -gy, np.ones_like(h)], axis=-1)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    n = 2 ** max(1, int(round(np.log2(max(tile_m / terrain.cell_size_m, 2.0)))))
    while ((nrow - 2) // n + 1) * ((ncol - 2) // n + 1) > max_tiles:
        n *= 2
    n_levels = int(np.log2(n))  # steps 1, 2, ..., n/2
    spans = [(i0, min(i0 + n, nrow - 1), j0, min(j0 + n, ncol - 1))
             for i0 in range(0, nrow - 1, n) for j0 in range(0, ncol - 1, n)]  # fmt: skip

    # per-level rows/cols and errors, then skirts deep enough to cover this tile's and its neighbours' errors
    levels, errors = [], np.full((len(spans), n_levels), np.inf)
    for t, (i0, i1, j0, j1) in enumerate(spans):
        tile_levels = []
        for L in range(n_levels):
            rows, cols = _level_indices(i0, i1, 2**L), _level_indices(j0, j1, 2**L)
            if L > 0 and len(rows) == len(tile_levels[-1][0]) and len(cols) == len(tile_levels[-1][1]):
                break  # the tile is too small for this level
            tile_levels.append((rows, cols))
            errors[t, L] = _decimation_error(h[i0 : i1 + 1, j0 : j1 + 1], rows - i0, cols - j0)
        levels.append(tile_levels)
    errors[:, 0] = 0.0  # level 0 is the hfield itself (the computed value is rounding noise)
    errors = np.maximum.accumulate(errors, axis=1)
    grid_shape = ((nrow - 2) // n + 1, (ncol - 2) // n + 1)
    worst = np.where(np.isfinite(errors), errors, 0.0).max(axis=1).reshape(grid_shape)
    padded = np.pad(worst, 1)
    neighbours = np.max([padded[1 + di : 1 + di + grid_shape[0], 1 + dj : 1 + dj + grid_shape[1]]
                         for di in (-1, 0, 1) for dj in (-1, 0, 1)], axis=0).ravel()  # fmt: skip
    skirts = worst.ravel() + neighbours + 1e-3

    boxes = np.zeros((len(spans), 2, 3))
    centres, tile_normals = np.zeros((len(spans), 3)), np.zeros((len(spans), 3))
    geom_names = np.full((len(spans), n_levels), "", dtype=object)
    meshes = []
    for t, tile_levels in enumerate(levels):
        for L, (rows, cols) in enumerate(tile_levels):
            verts, faces, norms, uv = _tile_mesh(terrain, normals, rows, cols, skirts[t])
            name = f"{TILE_PREFIX}{t:05d}_{L}"
            meshes.append(TileMesh(name, verts, faces, norms, uv))
            geom_names[t, L] = name
            if L == 0:
                boxes[t] = [verts.min(axis=0), verts.max(axis=0)]
                i0, i1, j0, j1 = spans[t]
                centres[t] = verts[: (i1 - i0 + 1) * (j1 - j0 + 1)].mean(axis=0)  # grid vertices, not the skirt
                n_mean = normals[i0 : i1 + 1, j0 : j1 + 1].reshape(-1, 3).mean(axis=0)
                tile_normals[t] = n_mean / np.linalg.norm(n_mean)
    return TerrainTiles(geom_names, boxes, errors, centres, tile_normals), meshes


def add_terrain_tiles(
    spec: mujoco.MjSpec, terrain: Terrain, tile_m: float, max_tiles: int, casts_shadows: bool = True
) -> TerrainTiles:
    """Add the render-only terrain tiles (all levels, contact-free, massless) to ``spec``; see :class:`TerrainTiles`.

    Normals come from the whole grid so shading is continuous across tiles and levels; texture coordinates
    address the one world-fixed terrain texture. The tile side is ``tile_m`` rounded to a power-of-two number
    of cells, doubled until there are at most ``max_tiles`` tiles (large terrains).
    """
    tiles, meshes = tile_meshes(terrain, tile_m, max_tiles)
    mat = spec.add_material()
    mat.name = TILE_MATERIAL
    src = spec.material("terrain")
    mat.textures = list(src.textures)
    mat.rgba, mat.specular, mat.shininess, mat.reflectance = src.rgba, 0.0, 0.0, 0.0
    for tm in meshes:
        mesh = spec.add_mesh()
        mesh.name = tm.name
        mesh.uservert = tm.verts.ravel().tolist()
        mesh.userface = tm.faces.ravel().tolist()
        mesh.usernormal = tm.normals.ravel().tolist()
        mesh.usertexcoord = tm.uv.ravel().tolist()
        mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL  # an open sheet has no volume
        g = spec.worldbody.add_geom()
        g.name, g.type, g.meshname, g.material = tm.name, mujoco.mjtGeom.mjGEOM_MESH, tm.name, TILE_MATERIAL
        g.contype, g.conaffinity, g.group, g.mass = 0, 0, GROUP_HIDDEN, 0.0
        g.castshadow = casts_shadows
    return tiles


def write_tile_meshes(model: mujoco.MjModel, meshes: list[TileMesh]) -> bool:
    """Overwrite the compiled tile meshes of ``model`` with ``meshes`` (another window of the same layout), in
    each mesh's compiled frame (MuJoCo stores mesh vertices relative to the mesh's inertial frame, which became
    its geom's pose): ``v_local = R^T (v_world - p)``, normals rotated alike. False (nothing written) when the
    layout differs; the caller then compiles a new model. Upload the meshes to GL afterwards."""
    ids = []
    for tm in meshes:
        mid = model.mesh(tm.name).id
        n = len(tm.verts)
        if not (model.mesh_vertnum[mid] == model.mesh_normalnum[mid] == model.mesh_texcoordnum[mid] == n):
            return False
        ids.append((mid, model.geom(tm.name).id))
    R = np.zeros(9)
    for tm, (mid, gid) in zip(meshes, ids, strict=True):
        mujoco.mju_quat2Mat(R, model.geom_quat[gid])
        rot, p, n = R.reshape(3, 3), model.geom_pos[gid], len(tm.verts)
        va, na, ta = model.mesh_vertadr[mid], model.mesh_normaladr[mid], model.mesh_texcoordadr[mid]
        model.mesh_vert[va : va + n] = (tm.verts - p) @ rot
        model.mesh_normal[na : na + n] = tm.normals @ rot
        model.mesh_texcoord[ta : ta + n] = tm.uv
    return True
