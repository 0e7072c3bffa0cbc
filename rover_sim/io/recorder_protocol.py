"""What the mission logs (:class:`Recorder`) and the recorder that records nothing (:class:`NullRecorder`).

The rerun implementation is :class:`rover_sim.io.recording.RerunRecorder`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from nav.camera import StereoRig
    from terrains import Terrain


@runtime_checkable
class Recorder(Protocol):
    """What the runner logs. ``RerunRecorder`` writes an ``.rrd``; ``NullRecorder`` does nothing.

    ``wants_images()`` tells the runner whether extra, recording-only products (dense stereo of the VO pairs) are
    worth computing.
    """

    def wants_images(self) -> bool: ...

    def log_terrain(self, terrain: Terrain, ground: bool = True) -> None: ...

    def log_ground_tile(
        self, key: str, t_s: float, step: int | None, tile: Terrain, centre_xy_m: tuple[float, float], mesh_step: int
    ) -> None: ...

    def log_terrain_tile(self, key: str, terrain: Terrain) -> None: ...

    def log_rover_pose(self, t_s: float, step: int | None, position_m: np.ndarray, quat_wxyz: np.ndarray) -> None: ...

    def log_camera(self, name: str, rig: StereoRig, t_s: float | None = None) -> None: ...

    def log_stereo_images(
        self,
        name: str,
        t_s: float,
        step: int | None,
        left_u8: np.ndarray,
        right_u8: np.ndarray,
        disparity_px: np.ndarray | None = None,
    ) -> None: ...

    def log_points(
        self, name: str, t_s: float, step: int | None, points_world: np.ndarray, colors: np.ndarray | None = None
    ) -> None: ...

    def log_trajectory(self, name: str, t_s: float, step: int | None, positions_m: np.ndarray) -> None: ...

    def log_goodness(
        self,
        t_s: float,
        step: int | None,
        centers_xy: np.ndarray,
        z: np.ndarray,
        goodness: np.ndarray,
        cell_size_m: float,
    ) -> None: ...

    def log_arcs(
        self,
        t_s: float,
        step: int | None,
        polylines: Sequence[np.ndarray],
        votes: Sequence[float | None],
        chosen: int | None,
    ) -> None: ...

    def log_vo_features(
        self,
        name: str,
        t_s: float,
        step: int | None,
        uv_prev: np.ndarray,
        uv_cur: np.ndarray,
        inlier: np.ndarray,
    ) -> None: ...

    def log_keep_out(self, name: str, x_m: float, y_m: float, radius_m: float, z_m: float) -> None: ...

    def log_scalars(self, t_s: float, step: int | None, values: Mapping[str, float]) -> None: ...

    def log_event(self, t_s: float, step: int | None, text: str, level: str = "INFO") -> None: ...

    def close(self) -> None: ...


class NullRecorder:
    """A recorder that records nothing (kiss-icp ``StubVisualizer``): run without ``if record:`` branches."""

    def wants_images(self) -> bool:
        return False

    def log_terrain(self, terrain: Terrain, ground: bool = True) -> None:
        pass

    def log_ground_tile(
        self, key: str, t_s: float, step: int | None, tile: Terrain, centre_xy_m: tuple[float, float], mesh_step: int
    ) -> None:
        pass

    def log_terrain_tile(self, key: str, terrain: Terrain) -> None:
        pass

    def log_rover_pose(self, t_s: float, step: int | None, position_m: np.ndarray, quat_wxyz: np.ndarray) -> None:
        pass

    def log_camera(self, name: str, rig: StereoRig, t_s: float | None = None) -> None:
        pass

    def log_stereo_images(
        self,
        name: str,
        t_s: float,
        step: int | None,
        left_u8: np.ndarray,
        right_u8: np.ndarray,
        disparity_px: np.ndarray | None = None,
    ) -> None:
        pass

    def log_points(
        self, name: str, t_s: float, step: int | None, points_world: np.ndarray, colors: np.ndarray | None = None
    ) -> None:
        pass

    def log_trajectory(self, name: str, t_s: float, step: int | None, positions_m: np.ndarray) -> None:
        pass

    def log_goodness(
        self,
        t_s: float,
        step: int | None,
        centers_xy: np.ndarray,
        z: np.ndarray,
        goodness: np.ndarray,
        cell_size_m: float,
    ) -> None:
        pass

    def log_arcs(
        self,
        t_s: float,
        step: int | None,
        polylines: Sequence[np.ndarray],
        votes: Sequence[float | None],
        chosen: int | None,
    ) -> None:
        pass

    def log_vo_features(
        self,
        name: str,
        t_s: float,
        step: int | None,
        uv_prev: np.ndarray,
        uv_cur: np.ndarray,
        inlier: np.ndarray,
    ) -> None:
        pass

    def log_keep_out(self, name: str, x_m: float, y_m: float, radius_m: float, z_m: float) -> None:
        pass

    def log_scalars(self, t_s: float, step: int | None, values: Mapping[str, float]) -> None:
        pass

    def log_event(self, t_s: float, step: int | None, text: str, level: str = "INFO") -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self) -> NullRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
