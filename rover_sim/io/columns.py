"""Batched time series for :class:`rover_sim.io.recording.RerunRecorder`: rows kept in memory per entity and sent
as one columnar chunk (rerun ``send_columns``) every ``flush_rows`` rows.

Why: every ``RecordingStream.log`` call that reaches the file on its own becomes a chunk that carries its own Arrow
schema and row ids, about 1.5 kB whatever it holds. A long traverse logs the rover pose, a handful of scalars and the
trajectories thousands of times; sent row by row they cost ~0.15 MB per metre of driving in chunk overhead alone
(a 1 km recording must stay under 150 MB). Sent in columns of ``flush_rows`` rows, the same rows cost a
few bytes each. The rows and their times are unchanged (same ``entity_row_counts``); only the chunking differs,
and it no longer depends on wall-clock timing (rerun's own micro-batcher flushes every 200 ms of wall time).

A stream is one of :data:`KINDS`; its rows must be added in time order. Memory is bounded: at most ``flush_rows``
rows per open entity (:meth:`ColumnBuffer.flush_entity` sends and forgets an entity that will get no more rows).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import rerun as rr

TIMELINE_SIM_TIME = "sim_time"
TIMELINE_STEP = "step"
DEFAULT_FLUSH_ROWS = 256


def _pose_columns(rows: list[tuple]) -> rr.ComponentColumnList:
    """Rows ``(translation_xyz, quaternion_xyzw)`` -> ``Transform3D`` columns."""
    return rr.Transform3D.columns(
        translation=np.array([r[0] for r in rows], dtype=np.float64),
        quaternion=np.array([r[1] for r in rows], dtype=np.float64),
    )


def _scalar_columns(rows: list[tuple]) -> rr.ComponentColumnList:
    """Rows ``(value,)`` -> ``Scalars`` columns."""
    return rr.Scalars.columns(scalars=np.array([r[0] for r in rows], dtype=np.float64))


def _point_columns(rows: list[tuple]) -> rr.ComponentColumnList:
    """Rows ``(xyz, rgb, radius_m, label)``, one point each -> ``Points3D`` columns."""
    n = len(rows)
    return rr.Points3D.columns(
        positions=np.array([r[0] for r in rows], dtype=np.float32),
        colors=np.array([r[1] for r in rows], dtype=np.uint8),
        radii=np.array([r[2] for r in rows], dtype=np.float32),
        labels=[r[3] for r in rows],
    ).partition(np.ones(n, dtype=np.int32))


def _strip_columns(rows: list[tuple]) -> rr.ComponentColumnList:
    """Rows ``(vertices (k, 3), rgb)``, one polyline each -> ``LineStrips3D`` columns."""
    return rr.LineStrips3D.columns(
        strips=[np.asarray(r[0], dtype=np.float32) for r in rows],
        colors=np.array([r[1] for r in rows], dtype=np.uint8),
    )


KINDS: dict[str, Callable[[list[tuple]], rr.ComponentColumnList]] = {
    "pose": _pose_columns,
    "scalar": _scalar_columns,
    "point": _point_columns,
    "strip": _strip_columns,
}


@dataclass
class _Series:
    kind: str
    times_s: list[float] = field(default_factory=list)
    steps: list[int] = field(default_factory=list)
    rows: list[tuple] = field(default_factory=list)


class ColumnBuffer:
    """Per-entity row buffers of one ``rr.RecordingStream``, each sent as columns when it holds ``flush_rows``."""

    def __init__(self, rec: rr.RecordingStream, flush_rows: int = DEFAULT_FLUSH_ROWS) -> None:
        if flush_rows < 1:
            raise ValueError(f"flush_rows must be >= 1, got {flush_rows}")
        self._rec = rec
        self.flush_rows = int(flush_rows)
        self._series: dict[str, _Series] = {}

    def add(self, path: str, kind: str, t_s: float, step: int, row: tuple) -> None:
        """One row of ``kind`` at ``path`` (time ``t_s`` on ``sim_time``, ``step`` on ``step``)."""
        s = self._series.get(path)
        if s is None:
            if kind not in KINDS:
                raise ValueError(f"ColumnBuffer kind {kind!r}: use one of {sorted(KINDS)}")
            s = self._series[path] = _Series(kind)
        elif s.kind != kind:
            raise ValueError(f"ColumnBuffer: {path!r} holds {s.kind!r} rows, got a {kind!r} row")
        s.times_s.append(float(t_s))
        s.steps.append(int(step))
        s.rows.append(row)
        if len(s.rows) >= self.flush_rows:
            self._send(path, s)

    def pending_rows(self) -> int:
        """Rows held in memory, not yet sent."""
        return sum(len(s.rows) for s in self._series.values())

    def flush_entity(self, path: str) -> None:
        """Send ``path``'s rows now and forget the entity (it gets no more rows, e.g. a closed trajectory block)."""
        s = self._series.pop(path, None)
        if s is not None:
            self._send(path, s)

    def flush(self) -> None:
        """Send every buffered row (before the stream is flushed or closed)."""
        for path, s in self._series.items():
            self._send(path, s)

    def _send(self, path: str, s: _Series) -> None:
        if not s.rows:
            return
        indexes = [
            rr.TimeColumn(TIMELINE_SIM_TIME, duration=np.asarray(s.times_s, dtype=np.float64)),
            rr.TimeColumn(TIMELINE_STEP, sequence=np.asarray(s.steps, dtype=np.int64)),
        ]
        self._rec.send_columns(path, indexes=indexes, columns=KINDS[s.kind](s.rows))
        s.times_s, s.steps, s.rows = [], [], []
