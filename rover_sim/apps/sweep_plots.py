"""The plots of a Monte-Carlo sweep (:func:`rover_sim.apps.sweep.run_sweep`): ``DIR/plots/*.png``.

Like :mod:`rover_sim.apps.sweep`, this module imports only the standard library at the top (numpy and
matplotlib are imported where a plot is drawn).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rover_sim.apps.sweep_jobs import GridAxis, Job, JobResult


@dataclass(frozen=True)
class _Point:
    """What the plots need of one completed job (slope and soil from its resolved scenario, grid or not)."""

    params: dict[str, Any]
    slope_deg: float
    soil: str
    max_slip_pct: float
    dr_error_pct: float | None
    vo_error_pct: float | None


def _points(jobs: Sequence[Job], results: Sequence[JobResult]) -> list[_Point]:
    pts = []
    for job, res in zip(jobs, results, strict=True):
        if res.ok and res.metrics is not None:
            terrain = job.scenario.get("terrain", {})
            pts.append(
                _Point(
                    job.params,
                    float(terrain.get("slope", {}).get("slope_deg", 0.0)),
                    str(terrain.get("material", {}).get("kind", "?")),
                    float(res.metrics["max_slip_pct"]),
                    res.metrics.get("dr_error_pct"),
                    res.metrics.get("vo_error_pct"),
                )
            )
    return pts


def _by_slope(pts: Sequence[_Point], value: Callable[[_Point], float | None]):
    """(slopes, mean, min, max) of ``value`` per slope, NaN-free."""
    import numpy as np

    groups: dict[float, list[float]] = {}
    for p in pts:
        v = value(p)
        if v is not None and np.isfinite(v):
            groups.setdefault(p.slope_deg, []).append(float(v))
    s = sorted(groups)
    return (
        np.array(s),
        np.array([np.mean(groups[k]) for k in s]),
        np.array([np.min(groups[k]) for k in s]),
        np.array([np.max(groups[k]) for k in s]),
    )


def _figure(size_in: tuple[float, float]):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size_in, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def plot_slip_vs_slope(pts: Sequence[_Point], path: Path, title: str) -> Path:
    """Max slip of each drive against slope, one series per soil: mean over seeds, whiskers to min and max."""
    from rover_sim.io.plots import DPI

    fig = _figure((6.4, 4.2))
    ax = fig.add_subplot()
    for i, soil in enumerate(sorted({p.soil for p in pts})):
        s, mean, lo, hi = _by_slope([p for p in pts if p.soil == soil], lambda p: p.max_slip_pct)
        ax.errorbar(s, mean, yerr=[mean - lo, hi - mean], color=f"C{i}", marker="o", capsize=3, label=soil)
    ax.set_xlabel("slope (deg)")
    ax.set_ylabel("max slip per drive (%)")
    ax.grid(True, alpha=0.3)
    ax.legend(title="soil", fontsize="small")
    ax.set_title(title)
    fig.savefig(path, dpi=DPI)
    return path


def plot_error_vs_slope(pts: Sequence[_Point], path: Path, title: str) -> Path:
    """Final position error (% of distance) of dead reckoning and VO against slope, per soil (mean over seeds)."""
    from rover_sim.io.plots import DPI

    fig = _figure((6.4, 4.2))
    ax = fig.add_subplot()
    for i, soil in enumerate(sorted({p.soil for p in pts})):
        mine = [p for p in pts if p.soil == soil]
        s, mean, lo, hi = _by_slope(mine, lambda p: p.dr_error_pct)
        ax.errorbar(
            s,
            mean,
            yerr=[mean - lo, hi - mean],
            color=f"C{i}",
            linestyle="--",
            marker="s",
            capsize=3,
            label=f"dead reckoning, {soil}",
        )
        s, mean, lo, hi = _by_slope(mine, lambda p: p.vo_error_pct)
        if len(s):
            ax.errorbar(
                s,
                mean,
                yerr=[mean - lo, hi - mean],
                color=f"C{i}",
                linestyle="-",
                marker="o",
                capsize=3,
                label=f"visual odometry, {soil}",
            )
    ax.set_xlabel("slope (deg)")
    ax.set_ylabel("position error (% of distance)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    ax.set_title(title)
    fig.savefig(path, dpi=DPI)
    return path


def plot_slip_map(pts: Sequence[_Point], x_axis: GridAxis, y_axis: GridAxis, path: Path, title: str) -> Path:
    """Heatmap of the mean (over seeds and any other axes) max slip over two grid axes; blank where none ran."""
    import numpy as np

    from rover_sim.io.plots import DPI

    grid = np.full((len(y_axis.values), len(x_axis.values)), np.nan)
    for iy, vy in enumerate(y_axis.values):
        for ix, vx in enumerate(x_axis.values):
            v = [p.max_slip_pct for p in pts if p.params[x_axis.key] == vx and p.params[y_axis.key] == vy]
            if v:
                grid[iy, ix] = float(np.mean(v))
    fig = _figure((1.6 + 0.9 * len(x_axis.values), 1.4 + 0.6 * len(y_axis.values)))
    ax = fig.add_subplot()
    im = ax.imshow(np.ma.masked_invalid(grid), origin="lower", aspect="auto", cmap="magma_r", vmin=0.0)
    for (iy, ix), v in np.ndenumerate(grid):
        if np.isfinite(v):
            ax.text(
                ix,
                iy,
                f"{v:.0f}",
                ha="center",
                va="center",
                fontsize="small",
                color="white" if v > 0.6 * np.nanmax(grid) else "black",
            )
    ax.set_xticks(range(len(x_axis.raw)), x_axis.raw)
    ax.set_yticks(range(len(y_axis.raw)), y_axis.raw)
    ax.set_xlabel(x_axis.key)
    ax.set_ylabel(y_axis.key)
    fig.colorbar(im, ax=ax, label="mean max slip (%)")
    ax.set_title(title)
    fig.savefig(path, dpi=DPI)
    return path


def plot_sweep(
    plot_dir: Path, axes: Sequence[GridAxis], jobs: Sequence[Job], results: Sequence[JobResult]
) -> list[Path]:
    """slip_vs_slope.png, error_vs_slope.png and, with two or more grid axes, slip_map.png over the first two."""
    pts = _points(jobs, results)
    if not pts:
        return []
    plot_dir.mkdir(parents=True, exist_ok=True)
    name = jobs[0].scenario.get("name", "")
    paths = [
        plot_slip_vs_slope(pts, plot_dir / "slip_vs_slope.png", f"{name}: slip vs slope"),
        plot_error_vs_slope(pts, plot_dir / "error_vs_slope.png", f"{name}: position error vs slope"),
    ]
    if len(axes) >= 2:
        paths.append(plot_slip_map(pts, axes[0], axes[1], plot_dir / "slip_map.png", f"{name}: slip map"))
    return paths
