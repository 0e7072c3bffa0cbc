"""Reading back an ``.rrd`` written by :class:`rover_sim.io.recording.RerunRecorder` (rerun 0.41)::

    from rerun.chunk import RrdReader
    chunks = RrdReader(path).stream().to_chunks()       # works with or without the RRD footer
    RrdReader(path).store().summary()                   # needs the footer that close() writes

or :func:`entity_row_counts`.
"""

from __future__ import annotations

from pathlib import Path


def entity_row_counts(path: str | Path) -> dict[str, int]:
    """Rows per entity path (static and temporal together) of an ``.rrd``, with or without its footer.

    Entity paths come back with a leading ``/`` (``"/world/rover"``); the recording's ``/__properties`` are
    included.
    """
    from rerun.chunk import RrdReader

    counts: dict[str, int] = {}
    for chunk in RrdReader(Path(path)).stream().to_chunks():
        counts[chunk.entity_path] = counts.get(chunk.entity_path, 0) + chunk.num_rows
    return counts
