"""The default layout of the rerun viewer for a recorded traverse (:class:`rover_sim.io.recording.RerunRecorder`)."""

from __future__ import annotations

import rerun.blueprint as rrb


def default_blueprint() -> rrb.Blueprint:
    """3D world view; navcam/hazcam image views with VO features; time-series tabs for ``plots``; event log."""
    image_contents = ["+ $origin/image", "+ $origin/features", "+ $origin/tracks"]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="world", origin="world"),
            rrb.Vertical(
                rrb.Tabs(
                    rrb.Spatial2DView(name="navcam left", origin="world/rover/navcam/left", contents=image_contents),
                    rrb.Spatial2DView(
                        name="navcam depth", origin="world/rover/navcam/left", contents=["+ $origin/depth"]
                    ),
                    rrb.Spatial2DView(
                        name="hazcam front left", origin="world/rover/hazcam_front/left", contents=image_contents
                    ),
                ),
                rrb.Tabs(
                    rrb.TimeSeriesView(name="position error", origin="plots/position_error_m"),
                    rrb.TimeSeriesView(name="slip", origin="plots/slip"),
                    rrb.TimeSeriesView(name="tilt", origin="plots/tilt_deg"),
                    rrb.TimeSeriesView(name="VO inliers", origin="plots/vo_inliers"),
                    rrb.TimeSeriesView(name="all plots", origin="plots"),
                ),
                rrb.TextLogView(name="events", origin="events"),
                row_shares=[3, 2, 1],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
