"""A growing series of poses held in arrays: the evaluator keeps every recorded pose of a run for its metrics.

A :class:`~nav.trajectory.Pose` costs ~450 bytes in Python objects (the dataclass and two small arrays); a pose here
costs 64 bytes (time, position, quaternion in float64), so a day-long drive's three pose histories (truth, dead
reckoning, onboard; one pose a second over ~25 000 s of a 1 km drive) stay near 5 MB instead of ~35 MB (the traverse
benchmark's memory bar: RSS after 1 km within 15 % of RSS after 100 m). Values are stored exactly: a pose read back
equals the pose appended, so metrics are unchanged.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from nav.trajectory import Pose, Trajectory

_COLS = 8  # t_s, x, y, z, qw, qx, qy, qz


class PoseSeries(Sequence[Pose]):
    """Append-only poses; ``series[k]`` (negative ``k`` too) and iteration give :class:`Pose` copies."""

    def __init__(self, capacity: int = 256) -> None:
        self._data = np.empty((max(int(capacity), 1), _COLS), dtype=float)
        self._n = 0

    def append(self, pose: Pose) -> None:
        if self._n == len(self._data):
            grown = np.empty((2 * len(self._data), _COLS), dtype=float)
            grown[: self._n] = self._data[: self._n]
            self._data = grown
        row = self._data[self._n]
        row[0] = pose.t_s
        row[1:4] = pose.position_xyz_m
        row[4:8] = pose.quat_wxyz
        self._n += 1

    def __len__(self) -> int:
        return self._n

    def __bool__(self) -> bool:
        return self._n > 0

    def __getitem__(self, k: int) -> Pose:  # type: ignore[override] - no slices
        if not isinstance(k, int | np.integer):
            raise TypeError(f"PoseSeries index must be an int, got {type(k).__name__}")
        i = int(k) + self._n if k < 0 else int(k)
        if not 0 <= i < self._n:
            raise IndexError(f"pose {k} of a series of {self._n}")
        row = self._data[i]
        return Pose(float(row[0]), row[1:4].copy(), row[4:8].copy())

    def __iter__(self) -> Iterator[Pose]:
        return (self[k] for k in range(self._n))

    @property
    def t_s(self) -> np.ndarray:
        """(N,) times, s (a view: valid until the next append)."""
        return self._data[: self._n, 0]

    @property
    def positions_xyz_m(self) -> np.ndarray:
        """(N, 3) world positions, m (a view: valid until the next append)."""
        return self._data[: self._n, 1:4]

    def trajectory(self) -> Trajectory:
        """The series as a :class:`Trajectory` (copied arrays)."""
        d = self._data[: self._n]
        return Trajectory(d[:, 0].copy(), d[:, 1:4].copy(), d[:, 4:8].copy())
