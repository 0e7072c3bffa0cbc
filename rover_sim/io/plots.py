"""Paper-style figures of a traverse (matplotlib, Agg canvas, no GUI, no pyplot global state).

* :func:`plot_error_vs_distance`: position error against distance travelled with the 10 %-of-distance design line
  (Fig. 4 style of the MER visual odometry paper: wheel/IMU dead reckoning vs VO).
* :func:`plot_paths`: top-down truth / dead-reckoning / VO paths over a hillshade tinted by material, with rock
  outlines and keep-out zones (Fig. 5 / Fig. 7 style).
* :func:`plot_slip`: slip per step or against time.
* :func:`plot_run`: the three of a run, titled with its scenario, seed and sensor profile (:func:`run_title`).

Each function writes a PNG (or any format matplotlib knows from the suffix) and returns the ``Figure`` so callers
and tests can inspect the artists. The map's legend sits outside the axes, where it cannot cover a rock or a
keep-out zone, and the map's limits hold every path, also where a path leaves the terrain (drawn blank there).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection
from matplotlib.colors import LightSource
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch

if TYPE_CHECKING:
    from nav.trajectory import Trajectory
    from terrains import Terrain

DESIGN_FRACTION = 0.10  # MER requirement: position error below 10 % of the distance travelled
DESIGN_LINE_GID = "design_line"
DPI = 150

# Consistent styles for the estimators the runner produces; other names get matplotlib's cycle.
_STYLE: dict[str, dict[str, object]] = {
    "truth": {"color": "black", "linestyle": "-", "label": "truth"},
    "dead_reckoning": {"color": "tab:orange", "linestyle": "--", "label": "wheel + IMU dead reckoning"},
    "vo": {"color": "tab:blue", "linestyle": "-", "label": "visual odometry"},
}
# Map tint per Material code (SAND, BEDROCK, MIXED), chosen for legibility under the hillshade.
_MATERIAL_RGB = np.array([[0.90, 0.72, 0.50], [0.60, 0.56, 0.56], [0.76, 0.64, 0.52], [0.96, 0.80, 0.60]])
_MATERIAL_NAMES = ("sand", "bedrock", "mixed", "drift")


def _style(name: str, index: int) -> dict[str, object]:
    return dict(_STYLE.get(name, {"color": f"C{(index + 2) % 10}", "linestyle": "-", "label": name}))


def _figure(size_in: tuple[float, float]) -> Figure:
    fig = Figure(figsize=size_in, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, bbox_inches="tight", pad_inches=0.1)  # the legend outside the map's axes included
    return path


# ------------------------------------------------------------------------------------------------- errors


def plot_error_vs_distance(
    distance_m: np.ndarray,
    errors: Mapping[str, np.ndarray],
    path: str | Path,
    *,
    design_fraction: float = DESIGN_FRACTION,
    title: str | None = None,
) -> Figure:
    """Position error (m) of each estimator against the distance travelled, with the design-requirement line.

    ``distance_m`` is the true distance travelled at each sample, ``errors[name]`` the position error there (same
    length; NaN where the estimator had no output). The design line ``error = design_fraction * distance`` has
    gid :data:`DESIGN_LINE_GID`.
    """
    d = np.asarray(distance_m, dtype=np.float64).reshape(-1)
    fig = _figure((6.4, 4.4))
    ax = fig.add_subplot()
    for i, (name, err) in enumerate(errors.items()):
        e = np.asarray(err, dtype=np.float64).reshape(-1)
        if e.shape != d.shape:
            raise ValueError(f"plot_error_vs_distance: errors[{name!r}] has {e.size} samples, distance_m {d.size}")
        style = _style(name, i)
        finite = np.flatnonzero(np.isfinite(e))
        if finite.size and d[finite[-1]] > 0:
            k = finite[-1]
            style["label"] = f"{style['label']} (final {e[k]:.2f} m, {100.0 * e[k] / d[k]:.1f} %)"
        ax.plot(d, e, linewidth=1.6, **style)
    d_max = float(np.nanmax(d)) if d.size else 1.0
    ax.plot(
        [0.0, d_max],
        [0.0, design_fraction * d_max],
        color="grey",
        linestyle=":",
        linewidth=1.4,
        label=f"{100 * design_fraction:g} % of distance",
        gid=DESIGN_LINE_GID,
    )
    ax.set_xlim(0.0, d_max if d_max > 0 else 1.0)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("distance travelled (m)")
    ax.set_ylabel("position error (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize="small")
    ax.set_title(title or "Position error vs distance travelled")
    _save(fig, path)
    return fig


# -------------------------------------------------------------------------------------------------- paths


def _view_bounds(
    terrain: Terrain, xy: list[np.ndarray], keep_out: list[tuple[str, float, float, float]], margin_m: float | None
) -> tuple[float, float, float, float]:
    """The map's (x0, x1, y0, y1): the paths' and zones' bounding box plus ``margin_m``, clipped to the terrain
    (a streamed site: its current window) but never so far that a path leaves the view; ``margin_m`` None: the
    whole terrain, widened likewise."""
    ox, oy = terrain.origin_xy_m  # a streamed site's window is centred there
    full = (ox - terrain.half_x_m, ox + terrain.half_x_m, oy - terrain.half_y_m, oy + terrain.half_y_m)
    paths = [p[np.isfinite(p).all(axis=1)] for p in xy if len(p)]
    paths = [p for p in paths if len(p)]
    zones = [np.array([[x - r, y - r], [x + r, y + r]]) for _, x, y, r in keep_out]
    if margin_m is None or not paths + zones:
        view = full
    else:
        allp = np.concatenate(paths + zones)
        lo, hi = allp.min(axis=0) - margin_m, allp.max(axis=0) + margin_m
        view = (max(lo[0], full[0]), min(hi[0], full[1]), max(lo[1], full[2]), min(hi[1], full[3]))
    if not paths:
        return view
    allp = np.concatenate(paths)
    pad = 0.02 * max(float(np.ptp(allp[:, 0])), float(np.ptp(allp[:, 1])), 1.0)  # a path never on the frame
    lo, hi = allp.min(axis=0) - pad, allp.max(axis=0) + pad
    return (min(view[0], lo[0]), max(view[1], hi[0]), min(view[2], lo[1]), max(view[3], hi[1]))


def plot_paths(
    terrain: Terrain,
    trajectories: Mapping[str, np.ndarray],
    path: str | Path,
    keep_out: Iterable[tuple[str, float, float, float]] = (),
    rocks: bool = True,
    *,
    margin_m: float | None = 3.0,
    title: str | None = None,
) -> Figure:
    """Top-down paths (``(N, 2)`` or ``(N, 3)`` world positions) over the terrain's hillshade and material map.

    The view is the paths' and keep-out zones' bounding box plus ``margin_m`` (``None``: the whole terrain).
    ``keep_out`` entries are ``(name, x_m, y_m, radius_m)``.
    """
    zones = [(str(n), float(x), float(y), float(r)) for n, x, y, r in keep_out]
    xy = {name: np.asarray(p, dtype=np.float64)[:, :2] for name, p in trajectories.items()}
    x0, x1, y0, y1 = _view_bounds(terrain, list(xy.values()), zones, margin_m)
    c = terrain.cell_size_m
    cols = np.flatnonzero((terrain.xs_m >= x0 - c) & (terrain.xs_m <= x1 + c))
    rows = np.flatnonzero((terrain.ys_m >= y0 - c) & (terrain.ys_m <= y1 + c))
    heights = terrain.heights_m[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
    materials = terrain.materials[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
    # LightSource expects image rows (north at the top); the grid has south in row 0.
    shade = LightSource(azdeg=315.0, altdeg=40.0).hillshade(heights[::-1], dx=c, dy=c)[::-1]
    rgb = _MATERIAL_RGB[np.minimum(materials, len(_MATERIAL_RGB) - 1)] * (0.3 + 0.7 * shade[..., None])
    extent = (
        terrain.xs_m[cols[0]] - c / 2,
        terrain.xs_m[cols[-1]] + c / 2,
        terrain.ys_m[rows[0]] - c / 2,
        terrain.ys_m[rows[-1]] + c / 2,
    )

    width, height = x1 - x0, y1 - y0
    aspect = height / width if width > 0 else 1.0
    fig = _figure((9.0, float(np.clip(7.0 * aspect, 3.5, 10.0)) + 0.6))  # 2 in. of the width for the legend
    ax = fig.add_subplot()
    ax.imshow(np.clip(rgb, 0.0, 1.0), origin="lower", extent=extent, interpolation="bilinear")
    handles: list[object] = [
        Patch(facecolor=_MATERIAL_RGB[m], edgecolor="none", label=_MATERIAL_NAMES[m])
        for m in np.unique(materials)
        if m < len(_MATERIAL_NAMES)
    ]

    if rocks and terrain.rocks:
        in_view = [
            r
            for r in terrain.rocks
            if x0 - r.footprint_radius_m <= r.x_m <= x1 + r.footprint_radius_m
            and y0 - r.footprint_radius_m <= r.y_m <= y1 + r.footprint_radius_m
        ]
        if in_view:
            outlines = [r.footprint_xy_m(16) for r in in_view]
            ax.add_collection(
                PolyCollection(
                    outlines, facecolors=(0.25, 0.2, 0.18, 0.55), edgecolors=(0.1, 0.08, 0.06), linewidths=0.6
                )
            )
            handles.append(Patch(facecolor=(0.25, 0.2, 0.18, 0.55), edgecolor=(0.1, 0.08, 0.06), label="rocks"))

    for name, x, y, r in zones:
        ax.add_patch(Circle((x, y), r, fill=False, edgecolor="red", linestyle="--", linewidth=1.4))
        ax.annotate(name, (x, y + r), ha="center", va="bottom", color="red", fontsize="small")
    if zones:
        handles.append(Line2D([], [], color="red", linestyle="--", label="keep-out"))

    for i, (name, p) in enumerate(xy.items()):
        style = _style(name, i)
        (line,) = ax.plot(p[:, 0], p[:, 1], linewidth=1.8, **style)
        handles.append(line)
        finite = p[np.isfinite(p).all(axis=1)]
        if len(finite):
            ax.plot(*finite[-1], marker="o", markersize=5, color=style["color"], markeredgecolor="white")
    starts = [p[np.isfinite(p).all(axis=1)][:1] for p in xy.values()]
    starts = [s for s in starts if len(s)]
    if starts:
        ax.plot(*starts[0][0], marker="^", markersize=9, color="green", markeredgecolor="black", linestyle="none")
        handles.append(
            Line2D([], [], marker="^", color="green", markeredgecolor="black", linestyle="none", label="start")
        )

    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_facecolor("white")  # where a path runs off the terrain
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    # outside the axes: inside, a legend can cover a rock or a keep-out zone
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize="small")
    ax.set_title(title or "Rover paths")
    _save(fig, path)
    return fig


# --------------------------------------------------------------------------------------------------- slip


def plot_slip(
    x: np.ndarray,
    slip: Mapping[str, np.ndarray],
    path: str | Path,
    *,
    x_label: str = "time (s)",
    title: str | None = None,
) -> Figure:
    """Slip series against ``x`` (time, step index or distance). Slip is a ratio (0.5 = 50 %); plotted in %.

    NaN (wheel not rolling, estimator without output) leaves a gap.
    """
    xs = np.asarray(x, dtype=np.float64).reshape(-1)
    fig = _figure((6.4, 3.8))
    ax = fig.add_subplot()
    for i, (name, s) in enumerate(slip.items()):
        v = np.asarray(s, dtype=np.float64).reshape(-1)
        if v.shape != xs.shape:
            raise ValueError(f"plot_slip: slip[{name!r}] has {v.size} samples, x {xs.size}")
        style = _style(name, i) if name in _STYLE else {"color": f"C{i % 10}", "label": name}
        ax.plot(xs, 100.0 * v, linewidth=1.3, **style)
    ax.axhline(0.0, color="grey", linewidth=0.8)
    ax.set_xlabel(x_label)
    ax.set_ylabel("slip (%)")
    ax.grid(True, alpha=0.3)
    if slip:
        ax.legend(loc="best", fontsize="small")
    ax.set_title(title or "Slip")
    _save(fig, path)
    return fig


# ---------------------------------------------------------------------------------------------------- a run


def run_title(scenario: str, seed: int, profile: str) -> str:
    """What every plot of a run is titled with: the scenario, its seed and the sensor profile."""
    return f"{scenario} (seed {seed}, {profile} profile)"


def plot_run(
    plot_dir: str | Path,
    title: str,
    terrain: Terrain,
    trajectories: Mapping[str, Trajectory],
    keep_out: Iterable[tuple[str, float, float, float]] = (),
    slip: tuple[np.ndarray, Mapping[str, np.ndarray]] | None = None,
) -> dict[str, Figure]:
    """A run's ``error_vs_distance.png`` (with more than one truth record), ``paths.png`` and, given ``slip``
    (times, series), ``slip.png`` in ``plot_dir``, each titled ``"<what>: <title>"``. ``trajectories`` hold the
    same records, ``"truth"`` among them; ``slip`` the samples metrics.json counts
    (:func:`rover_sim.runtime.evaluator.step_slips`)."""
    plot_dir = Path(plot_dir)
    truth = trajectories["truth"]
    figures: dict[str, Figure] = {}
    if len(truth) > 1:
        errors = {
            n: np.linalg.norm(t.positions_xyz - truth.positions_xyz, axis=1)
            for n, t in trajectories.items()
            if n != "truth"
        }
        figures["error_vs_distance"] = plot_error_vs_distance(
            truth.cumulative_distance_m(), errors, plot_dir / "error_vs_distance.png", title=f"Position error: {title}"
        )
    positions = {n: t.positions_xyz for n, t in trajectories.items()}
    figures["paths"] = plot_paths(
        terrain, positions, plot_dir / "paths.png", keep_out=keep_out, title=f"Paths: {title}"
    )
    if slip is not None and len(slip[0]):
        figures["slip"] = plot_slip(slip[0], slip[1], plot_dir / "slip.png", title=f"Slip per VO step: {title}")
    return figures
