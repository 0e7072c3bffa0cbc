"""Rerun recording of a simulated traverse: one ``log_<stream>()`` method per data stream.

The entity tree mirrors the frame tree (rerun ``nuscenes`` example style)::

    world                                   ViewCoordinates RIGHT_HAND_Z_UP (x east, y north, z up), static
    world/terrain                           Mesh3D coloured by material, static
    world/terrain/rocks                     Mesh3D of every rock, static
    world/terrain/tiles/t<x>_<y>[/rocks]    a streamed site: each tile once, coarse, when it first appears
    world/terrain/ground/t<i>_<j>           a deformable site (no world/terrain mesh): ground tiles on the timeline,
                                            re-logged at full resolution when ruts change them (io/rut_log.py)
    world/rover                             Transform3D (world <- rover) every tick
    world/rover/visual                      Boxes3D + Cylinders3D (body, deck, mast, 6 wheels), static
    world/rover/<camera>/{left,right}       Transform3D (rover <- camera, from T_rover_cam; re-logged only when it
                                            changes, e.g. navcam mast pointing) + Pinhole (RDF = OpenCV), static
    world/rover/<camera>/{left,right}/image Image (greyscale, JPEG-compressed by default)
    world/rover/<camera>/left/depth         DepthImage (uint16 mm, meter=1000) from the disparity map
    world/rover/<camera>/left/features      Points2D: VO features at the current pixel (inliers green, outliers red)
    world/rover/<camera>/left/tracks        LineStrips2D: previous -> current pixel of each feature
    world/points/<name>                     Points3D, world frame (stereo point clouds)
    world/trajectories/<name>/current       Points3D: the newest position
    world/trajectories/<name>/path/<k>      LineStrips3D: the polyline so far, in blocks of ``segment_points``
    world/goodness                          Points3D at GESTALT cell centres, red (0) -> green (1), unknown grey
    world/arcs/candidates                   LineStrips3D coloured by vote (vetoed arcs dark grey)
    world/arcs/chosen                       LineStrips3D, the winning arc (cleared when there is none)
    world/keep_out/<name>                   LineStrips3D circle draped on the terrain, static
    plots/<key>                             Scalars
    events                                  TextLog with levels

Timelines: ``sim_time`` (a duration, seconds) and ``step`` (a sequence). Every timed call sets both; a call
without ``step`` reuses the last step seen.

Per-call cost is kept small for long traverses (the recording grows linearly with distance): static
data is sent once; camera intrinsics and extrinsics are re-sent only when they change; a trajectory is decimated to
``min_spacing_m`` and split into blocks of at most ``segment_points`` vertices, so each call re-sends only the open
block (completed blocks stay visible, latest-at semantics), never the whole polyline; the high-rate streams (rover
pose, scalars, trajectories) are batched into columnar chunks (:mod:`rover_sim.io.columns`), since a chunk per log
call costs ~1.5 kB of overhead whatever it holds; images are JPEG, depth PNG.

Reading a recording back: :mod:`rover_sim.io.rrd` (:func:`entity_row_counts`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from rover_sim.io.blueprint import default_blueprint
from rover_sim.io.columns import DEFAULT_FLUSH_ROWS, TIMELINE_SIM_TIME, TIMELINE_STEP, ColumnBuffer
from rover_sim.io.recording_helpers import (
    ROCK_RGBA,
    PolylineState,
    colour_of,
    ground_mesh,
    ramp_red_green,
    rocks_mesh,
    rover_visual,
    terrain_mesh_step,
    tile_rocks,
    xyzw,
)

TILE_MESH_SIDE_PTS = 33  # a streamed tile's mesh in the recording: 25 cm spacing for an 8 m tile

if TYPE_CHECKING:
    from nav.camera import StereoRig
    from terrains import Terrain

APPLICATION_ID = "rover-sim"

POINTS_MAX = 50_000  # larger point clouds are subsampled (evenly, deterministic) before logging
CAMERA_PLANE_DISTANCE_M = 0.25  # how far in front of the camera the viewer draws the image plane / frustum
LEVELS = ("TRACE", "DEBUG", "INFO", "WARN", "ERROR", "CRITICAL")

_ROCK_RGBA = ROCK_RGBA
_UNKNOWN_RGBA = (128, 128, 128, 140)
_VETOED_RGBA = (70, 70, 70, 255)
_CHOSEN_RGBA = (0, 255, 255, 255)
_KEEP_OUT_RGBA = (255, 40, 40, 255)
_INLIER_RGBA = (40, 230, 60, 255)
_OUTLIER_RGBA = (255, 50, 40, 255)
_DRAPE_OFFSET_M = 0.03  # lines and points drawn on the ground sit this far above it so they are not z-fought


# ------------------------------------------------------------------------------------------------- recorder


class RerunRecorder:
    """Writes a traverse to an ``.rrd`` file through its own ``rr.RecordingStream`` (not the global one).

    ``jpeg_quality`` compresses camera images (``None``: raw pixels, about 10x larger; otherwise depth images are
    PNG-compressed too, losslessly). ``min_spacing_m`` and ``segment_points`` bound the trajectory cost (module
    docstring). Poses, scalars and trajectories are sent in columns of ``flush_rows`` rows
    (:mod:`rover_sim.io.columns`). Call :meth:`close` (or use ``with``) so the buffered rows are sent and the file
    gets its footer; a file cut short without one is still readable with ``RrdReader(...).stream()`` (without the
    rows still buffered when the process died).
    """

    def wants_images(self) -> bool:
        return True

    def __init__(
        self,
        path: str | Path,
        application_id: str = APPLICATION_ID,
        recording_name: str | None = None,
        *,
        recording_id: str | None = None,
        jpeg_quality: int | None = 90,
        min_spacing_m: float = 0.02,
        segment_points: int = 256,
        max_points: int = POINTS_MAX,
        blueprint: rrb.Blueprint | None = None,
        flush_rows: int = DEFAULT_FLUSH_ROWS,
    ) -> None:
        if segment_points < 2:
            raise ValueError(f"segment_points must be >= 2, got {segment_points}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.jpeg_quality = jpeg_quality
        self.min_spacing_m = float(min_spacing_m)
        self.segment_points = int(segment_points)
        self.max_points = int(max_points)
        self._rec = rr.RecordingStream(application_id, recording_id=recording_id)
        self._rec.set_log_time_enabled(False)  # sim_time and step only: no wall-clock timeline (deterministic rows)
        self._rec.save(self.path, default_blueprint=blueprint or default_blueprint())
        if recording_name:
            self._rec.send_recording_name(recording_name)
        self._columns = ColumnBuffer(self._rec, flush_rows)
        self._closed = False
        self._t_s = 0.0
        self._step = 0
        self._terrain: Terrain | None = None
        self._rigs: dict[str, StereoRig] = {}
        self._intrinsics: dict[str, tuple[float, ...]] = {}
        self._extrinsics: dict[str, np.ndarray] = {}
        self._tracks: dict[str, PolylineState] = {}
        self._log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._log_rover_visual()

    # -- plumbing --------------------------------------------------------------------------------------------

    def _log(self, path: str, *archetypes: object, static: bool = False) -> None:
        if self._closed:
            raise RuntimeError(f"RerunRecorder({self.path}) is closed; create a new recorder to log {path!r}")
        self._rec.log(path, *archetypes, static=static)  # type: ignore[arg-type]

    def _add(self, path: str, kind: str, row: tuple) -> None:
        """A row of a batched stream (:mod:`rover_sim.io.columns`) at the current time (set by ``_time``)."""
        if self._closed:
            raise RuntimeError(f"RerunRecorder({self.path}) is closed; create a new recorder to log {path!r}")
        self._columns.add(path, kind, self._t_s, self._step, row)

    def _time(self, t_s: float | None, step: int | None) -> None:
        if t_s is not None:
            self._t_s = float(t_s)
        if step is not None:
            self._step = int(step)
        self._rec.set_time(TIMELINE_SIM_TIME, duration=self._t_s)
        self._rec.set_time(TIMELINE_STEP, sequence=self._step)

    def _log_rover_visual(self) -> None:
        self._log("world/rover/visual", *rover_visual(), static=True)

    # -- static ----------------------------------------------------------------------------------------------

    def log_terrain(self, terrain: Terrain, ground: bool = True) -> None:
        """Static ground mesh (material colours, decimated) and rock meshes; ``ground=False``: rocks only (the
        ground comes as :meth:`log_ground_tile` tiles). Keep-out circles drape on it afterwards."""
        self._terrain = terrain
        if ground:
            self._log("world/terrain", ground_mesh(terrain, terrain_mesh_step(terrain.nrow, terrain.ncol)), static=True)
        if terrain.rocks:
            self._log("world/terrain/rocks", rocks_mesh(terrain.rocks), static=True)

    def log_ground_tile(
        self, key: str, t_s: float, step: int | None, tile: Terrain, centre_xy_m: tuple[float, float], mesh_step: int
    ) -> None:
        """One ground tile of a deformable site at ``t_s`` (re-logging replaces it from then on): ``tile``'s
        heightfield every ``mesh_step`` cells, its grid centred at ``centre_xy_m``."""
        self._time(t_s, step)
        self._log(f"world/terrain/ground/{key}", ground_mesh(tile, mesh_step, centre_xy_m))

    def log_terrain_tile(self, key: str, terrain: Terrain) -> None:
        """One tile of a streamed site, logged once when it first appears (static, coarse: about
        ``TILE_MESH_SIDE_PTS`` points a side, so the recording grows linearly and slowly with distance)."""
        if self._terrain is None:
            self._terrain = terrain  # keep-out circles drape on the first tile's window
        step = max(1, math.ceil((max(terrain.nrow, terrain.ncol) - 1) / (TILE_MESH_SIDE_PTS - 1)))
        self._log(f"world/terrain/tiles/{key}", ground_mesh(terrain, step), static=True)
        if terrain.rocks:
            self._log(f"world/terrain/tiles/{key}/rocks", tile_rocks(terrain.rocks), static=True)

    def log_keep_out(self, name: str, x_m: float, y_m: float, radius_m: float, z_m: float) -> None:
        """Static circle; draped on the terrain (if logged) else drawn at ``z_m``. Re-logging replaces it."""
        a = np.linspace(0.0, 2.0 * np.pi, 73)
        x, y = x_m + radius_m * np.cos(a), y_m + radius_m * np.sin(a)
        if self._terrain is not None:
            z = np.asarray(self._terrain.height_at(x, y)) + _DRAPE_OFFSET_M
        else:
            z = np.full_like(x, z_m + _DRAPE_OFFSET_M)
        self._log(
            f"world/keep_out/{name}",
            rr.LineStrips3D([np.column_stack([x, y, z])], colors=[_KEEP_OUT_RGBA], radii=[0.02], labels=[name]),
            static=True,
        )

    # -- cameras ---------------------------------------------------------------------------------------------

    def log_camera(self, name: str, rig: StereoRig, t_s: float | None = None) -> None:
        """Pinholes (static, re-sent if the intrinsics change) and rover <- camera extrinsics of both cameras.

        Extrinsics are logged on the timelines at ``t_s`` (default: the latest time logged), and only when
        ``T_rover_cam`` changed since the last call, so calling this every tick costs a comparison.
        """
        self._rigs[name] = rig
        for side, cam in (("left", rig.left), ("right", rig.right)):
            path = f"world/rover/{name}/{side}"
            intr = (cam.width_px, cam.height_px, cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px)
            if self._intrinsics.get(path) != intr:
                self._intrinsics[path] = intr
                self._log(
                    path,
                    rr.Pinhole(
                        image_from_camera=cam.K,
                        resolution=[cam.width_px, cam.height_px],
                        camera_xyz=rr.ViewCoordinates.RDF,
                        image_plane_distance=CAMERA_PLANE_DISTANCE_M,
                    ),
                    static=True,
                )
            T = np.asarray(cam.T_rover_cam, dtype=np.float64)
            last = self._extrinsics.get(path)
            if last is None or not np.array_equal(last, T):
                self._extrinsics[path] = T.copy()
                self._time(t_s, None)
                self._log(path, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))

    def log_stereo_images(
        self,
        name: str,
        t_s: float,
        step: int | None,
        left_u8: np.ndarray,
        right_u8: np.ndarray,
        disparity_px: np.ndarray | None = None,
    ) -> None:
        """Left/right images under the camera entities; the disparity as a metric ``DepthImage`` under left.

        A disparity map needs the rig (call :meth:`log_camera` first) to turn pixels into metres.
        """
        self._time(t_s, step)
        for side, img in (("left", left_u8), ("right", right_u8)):
            self._log(f"world/rover/{name}/{side}/image", self._image(img))
        if disparity_px is not None:
            rig = self._rigs.get(name)
            if rig is None:
                raise ValueError(f"log_stereo_images({name!r}) got a disparity map before log_camera({name!r}, rig)")
            depth_mm = np.rint(1000.0 * rig.depth_from_disparity(disparity_px))
            depth_mm[~(depth_mm < 65535.0)] = 0.0  # 0 = no data (NaN, or beyond the 65.5 m a uint16 holds)
            depth = rr.DepthImage(depth_mm.astype(np.uint16), meter=1000.0)
            self._log(f"world/rover/{name}/left/depth", depth if self.jpeg_quality is None else depth.compress())

    def _image(self, img: np.ndarray) -> rr.Image | rr.EncodedImage:
        a = np.asarray(img)
        if a.dtype != np.uint8:
            a = np.clip(a, 0, 255).astype(np.uint8)
        image = rr.Image(a, color_model="L" if a.ndim == 2 else "RGB")
        return image if self.jpeg_quality is None else image.compress(jpeg_quality=self.jpeg_quality)

    def log_vo_features(
        self,
        name: str,
        t_s: float,
        step: int | None,
        uv_prev: np.ndarray,
        uv_cur: np.ndarray,
        inlier: np.ndarray,
    ) -> None:
        """VO features on the left image at their current pixel, and their track from the previous pixel."""
        self._time(t_s, step)
        prev = np.asarray(uv_prev, dtype=np.float32).reshape(-1, 2)
        cur = np.asarray(uv_cur, dtype=np.float32).reshape(-1, 2)
        ok = np.asarray(inlier, dtype=bool).reshape(-1)
        valid = np.isfinite(cur).all(axis=1)
        colors = np.where(ok[:, None], np.array(_INLIER_RGBA), np.array(_OUTLIER_RGBA)).astype(np.uint8)
        base = f"world/rover/{name}/left"
        self._log(f"{base}/features", rr.Points2D(cur[valid], colors=colors[valid], radii=[2.0]))
        tracked = valid & np.isfinite(prev).all(axis=1)
        self._log(
            f"{base}/tracks",
            rr.LineStrips2D(np.stack([prev[tracked], cur[tracked]], axis=1), colors=colors[tracked], radii=[0.75]),
        )

    # -- world -----------------------------------------------------------------------------------------------

    def log_rover_pose(self, t_s: float, step: int | None, position_m: np.ndarray, quat_wxyz: np.ndarray) -> None:
        """world <- rover transform (translation + quaternion), batched (sent every ``flush_rows`` poses)."""
        self._time(t_s, step)
        self._add("world/rover", "pose", (np.asarray(position_m, dtype=np.float64), xyzw(quat_wxyz)))

    def log_points(
        self, name: str, t_s: float, step: int | None, points_world: np.ndarray, colors: np.ndarray | None = None
    ) -> None:
        """World-frame point cloud at ``world/points/<name>``; non-finite points dropped, large clouds thinned."""
        self._time(t_s, step)
        p = np.asarray(points_world, dtype=np.float32).reshape(-1, 3)
        keep = np.isfinite(p).all(axis=1)
        idx = np.flatnonzero(keep)
        if len(idx) > self.max_points:
            idx = idx[np.linspace(0, len(idx) - 1, self.max_points).astype(np.intp)]
        c = None if colors is None else np.asarray(colors)[idx]
        self._log(f"world/points/{name}", rr.Points3D(p[idx], colors=c, radii=[0.01]))

    def log_trajectory(self, name: str, t_s: float, step: int | None, positions_m: np.ndarray) -> None:
        """The trajectory so far (pass the whole history each time; only what is new is processed and sent)."""
        p = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
        if len(p) == 0:
            return
        self._time(t_s, step)
        base = f"world/trajectories/{name}"
        st = self._tracks.get(name)
        rewritten = st is not None and (
            st.n_in > len(p) or not np.array_equal(p[st.n_in - 1], st.last_in, equal_nan=True)
        )
        if st is None or rewritten:
            if st is not None:  # history was rewritten: start over
                self._columns.flush_entity(f"{base}/path/{st.block:05d}")
                self._log(f"{base}/path", rr.Clear(recursive=True))
            st = self._tracks[name] = PolylineState()
        rgb = colour_of(name)
        changed = False
        min2 = self.min_spacing_m**2
        for q in p[st.n_in :]:
            if not np.isfinite(q).all():
                continue
            if st.kept and float(np.sum((q - st.kept[-1]) ** 2)) < min2:
                continue
            st.kept.append(q.copy())  # not a view: it would keep the caller's whole buffer alive
            changed = True
            if len(st.kept) >= self.segment_points:  # close this block, open the next at its last vertex
                self._add(f"{base}/path/{st.block:05d}", "strip", (np.asarray(st.kept), rgb))
                self._columns.flush_entity(f"{base}/path/{st.block:05d}")
                st.block += 1
                st.kept = [q]
                changed = False
        st.n_in, st.last_in = len(p), p[-1].copy()
        if changed and len(st.kept) >= 2:
            self._add(f"{base}/path/{st.block:05d}", "strip", (np.asarray(st.kept), rgb))
        current = st.kept[-1] if st.kept else None
        if np.isfinite(p[-1]).all():
            current = p[-1]
        if current is not None:
            self._add(f"{base}/current", "point", (current, rgb, 0.05, name))

    def log_goodness(
        self,
        t_s: float,
        step: int | None,
        centers_xy: np.ndarray,
        z: np.ndarray,
        goodness: np.ndarray,
        cell_size_m: float,
    ) -> None:
        """GESTALT goodness map: a point per cell, red (0) -> green (1), grey where unknown (NaN)."""
        self._time(t_s, step)
        xy = np.asarray(centers_xy, dtype=np.float64).reshape(-1, 2)
        g = np.asarray(goodness, dtype=np.float64).reshape(-1)
        zz = np.asarray(z, dtype=np.float64).reshape(-1)
        known = np.isfinite(g)
        colors = np.empty((len(g), 4), dtype=np.uint8)
        colors[:] = _UNKNOWN_RGBA
        colors[known, :3] = ramp_red_green(g[known])
        colors[known, 3] = 255
        zz = np.where(np.isfinite(zz), zz, 0.0) + _DRAPE_OFFSET_M
        self._log(
            "world/goodness",
            rr.Points3D(np.column_stack([xy, zz]).astype(np.float32), colors=colors, radii=[0.35 * cell_size_m]),
        )

    def log_arcs(
        self,
        t_s: float,
        step: int | None,
        polylines: Sequence[np.ndarray],
        votes: Sequence[float | None],
        chosen: int | None,
    ) -> None:
        """Candidate arcs coloured by vote (normalised by the best vote; ``None`` = vetoed), the winner apart."""
        if len(polylines) != len(votes):
            raise ValueError(f"log_arcs: {len(polylines)} polylines but {len(votes)} votes")
        self._time(t_s, step)
        v = np.array([np.nan if x is None else float(x) for x in votes], dtype=np.float64)
        finite = np.isfinite(v)
        top = float(np.max(v[finite])) if finite.any() else 0.0
        colors = np.empty((len(v), 4), dtype=np.uint8)
        colors[:] = _VETOED_RGBA
        if finite.any():
            colors[finite, :3] = ramp_red_green(v[finite] / top if top > 0 else np.zeros(finite.sum()))
            colors[finite, 3] = 255
        strips = [np.asarray(s, dtype=np.float32).reshape(-1, 3) for s in polylines]
        self._log("world/arcs/candidates", rr.LineStrips3D(strips, colors=colors, radii=[0.01]))
        if chosen is None:
            self._log("world/arcs/chosen", rr.Clear(recursive=False))
        else:
            self._log("world/arcs/chosen", rr.LineStrips3D([strips[chosen]], colors=[_CHOSEN_RGBA], radii=[0.03]))

    # -- plots and events ------------------------------------------------------------------------------------

    def log_scalars(self, t_s: float, step: int | None, values: Mapping[str, float]) -> None:
        """One ``Scalars`` per key at ``plots/<key>`` (``/`` in a key nests), batched; non-finite values skipped."""
        self._time(t_s, step)
        for key, value in values.items():
            x = float(value)
            if math.isfinite(x):
                self._add(f"plots/{key}", "scalar", (x,))

    def log_event(self, t_s: float, step: int | None, text: str, level: str = "INFO") -> None:
        """A line in the ``events`` log; ``level`` is one of :data:`LEVELS` (``WARNING`` = ``WARN``)."""
        lvl = level.upper()
        lvl = "WARN" if lvl == "WARNING" else lvl
        if lvl not in LEVELS:
            raise ValueError(f"log_event level {level!r}: use one of {LEVELS}")
        self._time(t_s, step)
        self._log("events", rr.TextLog(text, level=lvl))

    # -- lifetime --------------------------------------------------------------------------------------------

    def close(self) -> None:
        """Flush and close the file (writes the RRD footer). Safe to call twice."""
        if self._closed:
            return
        self._closed = True
        try:
            self._columns.flush()
            self._rec.flush()
        finally:
            self._rec.disconnect()

    def __enter__(self) -> RerunRecorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
