"""The physics heightfield of a streamed site: a window of tiles that moves with the rover (``[terrain.streamed]``).

MuJoCo's heightfield has a fixed grid size once compiled, but its data (``model.hfield_data``) and its geom's
position (``model.geom_pos``) may change between steps. :class:`TerrainStreamer` keeps the window centred on the
rover's tile: when the rover enters another tile it assembles the window around it from the site's tiles
(:class:`terrains.stream.StreamedSite`, deterministic per tile), writes the heights into ``hfield_data`` and moves
the hfield geom to the window's centre. Every world point keeps its height (the tiles are functions of world
coordinates), so the rover's state needs no change and contacts carry on (see tests/rover_sim/test_stream.py).
The encoding's elevation range is fixed at compile time (:data:`MIN_ELEVATION_RANGE_M` or more) so every later
window fits it; only the base moves. Rocks are a pool of ellipsoid geoms (``sim/assembly.py``) moved and resized
in place; the world body's bounding-volume tree is then rebuilt (``sim/bvh.py``) so MuJoCo's midphase stays on.
"""

from __future__ import annotations

import ctypes
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from rover_sim.sim.assembly import ROCK_GEOM_PREFIX, hfield_encoding, park_point_m, rock_slot_geometry
from rover_sim.sim.bvh import rebuild_body_bvh
from terrains.stream import StreamedSite, WindowTerrain

if TYPE_CHECKING:
    from terrains import TerrainRecipe

MIN_ELEVATION_RANGE_M = 60.0  # hfield encoding range: float32 steps of ~4 um over it (crater walls fit)


def release_freed_memory() -> None:
    """Hand memory the process has freed back to the OS (glibc ``malloc_trim``; a no-op elsewhere).

    A window move frees the previous window's arrays and a render model's tile meshes, but glibc keeps freed blocks
    in its arenas, fragmented between long-lived ones, so a long streamed drive's RSS crept up ~5 MB per re-centre
    with nothing alive to show for it (measured: 16 re-centres with rendering, 884 -> 955 MB and rising; with a trim
    after each, 783 -> 837 MB, flat once the tile caches are full)."""
    global _LIBC
    if _LIBC is None:
        try:
            _LIBC = ctypes.CDLL("libc.so.6")
            _LIBC.malloc_trim.argtypes = [ctypes.c_size_t]
        except (OSError, AttributeError):
            _LIBC = False
    if _LIBC:
        _LIBC.malloc_trim(0)


_LIBC: ctypes.CDLL | bool | None = None


class TerrainStreamer:
    """Re-centres a compiled model's heightfield window (and rock pool) on the rover's tile."""

    def __init__(self, recipe: TerrainRecipe, seed: int) -> None:
        self.site = StreamedSite(recipe, seed, cache_tiles=4 * recipe.streamed.window_tiles**2)
        self.rock_slots = recipe.streamed.rock_slots
        self.recentres = 0
        self.rocks_dropped = 0  # rocks beyond the slot pool in some window (the smallest are left out)
        self.clipped_windows = 0  # windows whose relief exceeded the encoding range
        self.elevation_range_m = MIN_ELEVATION_RANGE_M
        self._logged: set[tuple[int, int]] = set()  # tiles handed to the recording already

    def initial_window(self, x_m: float, y_m: float) -> WindowTerrain:
        w = self._fit(self.site.window(self.site.tile_of(x_m, y_m)))
        self.elevation_range_m = max(MIN_ELEVATION_RANGE_M, 2.0 * float(np.ptp(w.heights_m)))
        return w

    def _fit(self, w: WindowTerrain) -> WindowTerrain:
        """Keep at most ``rock_slots - 2`` rocks (the tallest): two slots anchor the world bound (sim/assembly.py)."""
        room = self.rock_slots - 2
        if len(w.rocks) > room:
            self.rocks_dropped += len(w.rocks) - room
            w.rocks = sorted(w.rocks, key=lambda r: -r.height_m)[:room]
        return w

    def window_for(self, current: WindowTerrain, x_m: float, y_m: float) -> WindowTerrain | None:
        """The window to switch to when the rover at (x, y) has left ``current``'s centre tile, else None."""
        tile = self.site.tile_of(x_m, y_m)
        if tile == current.window_index:
            return None
        return self._fit(self.site.window(tile))

    def new_tiles(self, window: WindowTerrain) -> list[tuple[str, WindowTerrain]]:
        """Tiles of ``window`` not handed out before, each as a terrain of one tile plus its east and north
        neighbours' first row/column (so logged tiles join): ``(key, terrain)`` for the recording."""
        k = self.site.stream.window_tiles
        cx, cy = window.window_index
        out = []
        for tx in range(cx - k // 2, cx + k // 2 + 1):
            for ty in range(cy - k // 2, cy + k // 2 + 1):
                if (tx, ty) not in self._logged:
                    self._logged.add((tx, ty))
                    out.append((f"t{tx}_{ty}", self.site.closed_tile(tx, ty)))
        return out

    def apply(self, model: mujoco.MjModel, window: WindowTerrain) -> None:
        """Write ``window`` into ``model``: hfield data and position, rock slots (same layout as compiled).

        Also right after compiling: MuJoCo rescales compiled hfield data to span [0, 1], which would stretch a
        window's relief over the whole fixed elevation range."""
        hid = model.hfield("terrain").id
        nrow, ncol = int(model.hfield_nrow[hid]), int(model.hfield_ncol[hid])
        if window.heights_m.shape != (nrow, ncol):
            raise ValueError(f"window grid {window.heights_m.shape} differs from the compiled hfield {(nrow, ncol)}")
        data, rng, base = hfield_encoding(window.heights_m, self.elevation_range_m)
        if float(np.ptp(window.heights_m)) > rng:
            self.clipped_windows += 1
        adr = int(model.hfield_adr[hid])
        model.hfield_data[adr : adr + nrow * ncol] = data.ravel()
        model.geom_pos[model.geom("terrain").id] = [*window.origin_xy_m, base]
        park = park_point_m(window)
        for i in range(self.rock_slots):
            gid = model.geom(f"{ROCK_GEOM_PREFIX}{i:04d}").id
            pos, quat, size = rock_slot_geometry(window.rocks[i] if i < len(window.rocks) else None, park)
            model.geom_pos[gid], model.geom_quat[gid], model.geom_size[gid] = pos, quat, size
            model.geom_rbound[gid] = max(size)
            model.geom_aabb[gid] = [0.0, 0.0, 0.0, *size]
            model.geom_conaffinity[gid] = 1 if i < len(window.rocks) else 0  # parked slots skip the pair tests
        rebuild_body_bvh(model)  # the world body's midphase tree, for the moved hfield and rocks (sim/bvh.py)
