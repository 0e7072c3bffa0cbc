"""The layout of the rerun viewer for a recorded traverse, built from what the run used.

A run that drives autonav opens on the front hazcam (images with its stereo depth beside) and a top-down GESTALT
view (goodness map, candidate arcs coloured by vote, the chosen arc, the paths); a run with VO opens on its VO
camera with the feature tracks and slip series; series that a run cannot produce (VO error without VO) are absent.
"""

from __future__ import annotations

from dataclasses import dataclass

import rerun.blueprint as rrb

IMAGE_CONTENTS = ["+ $origin/image", "+ $origin/features", "+ $origin/tracks"]
TOP_DOWN_HEIGHT_M = 12.0  # eye height of the top-down goodness view above the rover (the 10 m goodness window fills it)


@dataclass(frozen=True)
class RunLayout:
    """What a run records, as far as the viewer layout is concerned."""

    vo_camera: str | None = "navcam"  # None: VO off
    autonav: bool = False  # GESTALT cycles with front (and, when backing up, rear) hazcam stereo

    @property
    def cameras(self) -> list[str]:
        out = ["hazcam_front"] if self.autonav else []
        if self.vo_camera and self.vo_camera not in out:
            out.append(self.vo_camera)
        return out


def _camera_views(camera: str) -> list[rrb.View]:
    label = camera.replace("_", " ")
    origin = f"world/rover/{camera}/left"
    return [
        rrb.Spatial2DView(name=f"{label} left", origin=origin, contents=IMAGE_CONTENTS),
        rrb.Spatial2DView(name=f"{label} depth", origin=origin, contents=["+ $origin/depth"]),
    ]


def _top_down_view() -> rrb.View:
    return rrb.Spatial3DView(
        name="GESTALT goodness (top-down)",
        origin="world",
        contents=["+ world/goodness", "+ world/arcs/**", "+ world/trajectories/**", "+ world/rover/visual"],
        eye_controls=rrb.EyeControls3D(
            kind=rrb.Eye3DKind.Orbital,
            tracking_entity="world/rover",
            position=[0.0, -0.01, TOP_DOWN_HEIGHT_M],
            look_target=[0.0, 0.0, 0.0],
            eye_up=[0.0, 1.0, 0.0],
        ),
    )


def _series(layout: RunLayout) -> list[rrb.View]:
    views = [rrb.TimeSeriesView(name="position error", origin="plots/position_error_m")]
    if layout.vo_camera:
        views += [
            rrb.TimeSeriesView(name="slip per VO step", origin="plots/slip_pct"),
            rrb.TimeSeriesView(name="VO inliers", origin="plots/vo_inliers"),
        ]
    views += [
        rrb.TimeSeriesView(name="wheel slip", origin="plots/wheel_slip_pct"),
        rrb.TimeSeriesView(name="tilt", origin="plots/tilt_deg"),
        rrb.TimeSeriesView(name="all plots", origin="plots"),
    ]
    return views


def blueprint_for(layout: RunLayout) -> rrb.Blueprint:
    """3D world beside the run's own camera views (autonav: hazcam + top-down goodness first), series, events."""
    cameras: list[rrb.View] = []
    if layout.autonav:
        cameras.append(_top_down_view())
    for camera in layout.cameras:
        cameras.extend(_camera_views(camera))
    right: list[rrb.Container | rrb.View] = []
    if cameras:
        right.append(rrb.Tabs(*cameras, active_tab=0))
    right += [rrb.Tabs(*_series(layout), active_tab=0), rrb.TextLogView(name="events", origin="events")]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="world", origin="world"),
            rrb.Vertical(*right, row_shares=[3, 2, 1][-len(right) :]),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def default_blueprint() -> rrb.Blueprint:
    """The layout of a navcam-VO run (used when the recorder is not told what the run does)."""
    return blueprint_for(RunLayout())


def view_names(blueprint: rrb.Blueprint) -> list[str]:
    """Every view's name in layout order, first tab first (for tests and ``rover-sim view``)."""
    out: list[str] = []

    def walk(node: object) -> None:
        contents = getattr(node, "contents", None)
        if isinstance(node, rrb.View) or contents is None or isinstance(contents, list | str):
            name = getattr(node, "name", None)
            if name is not None:
                out.append(str(name))
            if not isinstance(contents, tuple | list) or isinstance(node, rrb.View):
                return
        for child in contents:
            walk(child)

    for part in blueprint.root_container.contents if blueprint.root_container else []:
        walk(part)
    return out
