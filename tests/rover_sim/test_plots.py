"""Paper-style figures: each writes a non-empty PNG and draws what it claims to."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.collections import PolyCollection
from matplotlib.patches import Circle

from rover_sim.io.plots import DESIGN_LINE_GID, plot_error_vs_distance, plot_paths, plot_slip
from terrains import ExplicitRockSpec, Terrain, TerrainRecipe, synthesize

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def terrain() -> Terrain:
    wopmay = ExplicitRockSpec(name="wopmay", x_m=1.0, y_m=0.5, length_m=1.5, width_m=0.9, height_m=0.6)
    return synthesize(TerrainRecipe(size_m=(8, 6), cell_size_m=0.1, explicit_rocks=[wopmay]), seed=0)


def _png_ok(path: Path) -> None:
    assert path.stat().st_size > 5_000
    assert path.read_bytes()[:8] == PNG_MAGIC


def test_error_vs_distance_has_the_design_line(tmp_path: Path) -> None:
    d = np.linspace(0.0, 20.0, 50)
    errors = {"dead_reckoning": 0.12 * d, "vo": 0.01 * d}
    errors["vo"][:3] = np.nan  # no VO output yet: a gap, not an error
    fig = plot_error_vs_distance(d, errors, tmp_path / "err.png")
    _png_ok(tmp_path / "err.png")
    (ax,) = fig.axes
    (design,) = [ln for ln in ax.get_lines() if ln.get_gid() == DESIGN_LINE_GID]
    x, y = np.asarray(design.get_xdata(), float), np.asarray(design.get_ydata(), float)
    np.testing.assert_allclose(y, 0.10 * x)
    assert x.max() == pytest.approx(20.0)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("visual odometry" in t and "1.0 %" in t for t in labels)
    assert any(t.startswith("10 % of distance") for t in labels)
    with pytest.raises(ValueError, match="samples"):
        plot_error_vs_distance(d, {"vo": d[:5]}, tmp_path / "bad.png")


def test_paths_over_the_terrain(tmp_path: Path, terrain: Terrain) -> None:
    s = np.linspace(0.0, 1.0, 40)
    truth = np.column_stack([-2.0 + 4.0 * s, 0.4 * np.sin(3 * s), np.zeros_like(s)])
    trajectories = {"truth": truth, "dead_reckoning": truth * [1.08, 1.2, 1.0], "vo": truth + 0.02}
    fig = plot_paths(terrain, trajectories, tmp_path / "paths.png", keep_out=[("wopmay", 1.0, 0.5, 0.8)])
    _png_ok(tmp_path / "paths.png")
    (ax,) = fig.axes
    assert ax.get_aspect() == 1.0
    assert len(ax.get_images()) == 1
    assert any(isinstance(c, PolyCollection) for c in ax.collections)  # rock outlines
    assert any(isinstance(p, Circle) for p in ax.patches)  # keep-out
    labels = {t.get_text() for t in ax.get_legend().get_texts()}
    assert {"truth", "wheel + IMU dead reckoning", "visual odometry", "keep-out", "rocks"} <= labels
    x0, x1 = ax.get_xlim()
    assert x0 <= -2.0 and x1 >= 2.0
    fig = plot_paths(terrain, {"truth": truth[:, :2]}, tmp_path / "whole.png", rocks=False, margin_m=None)
    _png_ok(tmp_path / "whole.png")
    assert fig.axes[0].get_xlim() == pytest.approx((-terrain.half_x_m, terrain.half_x_m))


def test_slip_plot(tmp_path: Path) -> None:
    t = np.arange(30.0)
    slip = {"truth": np.clip(0.02 * t, 0, 0.5), "vo": 0.02 * t + 0.01}
    slip["vo"][::5] = np.nan
    fig = plot_slip(t, slip, tmp_path / "slip.png", x_label="step")
    _png_ok(tmp_path / "slip.png")
    ax = fig.axes[0]
    assert ax.get_ylabel() == "slip (%)"
    np.testing.assert_allclose(np.nanmax(ax.get_lines()[0].get_ydata()), 50.0)


# ------------------------------------------------------------------------------------------ a run's plots
def _overlap(a, b) -> bool:  # noqa: ANN001 - two matplotlib Bbox in display coordinates
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def _map_with_hazards(terrain: Terrain, path: Path):  # noqa: ANN202
    """Keep-out zones in every corner and mid-side of the view (a legend inside the axes covers one of them); the
    dead-reckoning path runs 6 m past the terrain's east edge."""
    s = np.linspace(0.0, 1.0, 60)
    truth = np.column_stack([-3.0 + 6.0 * s, 0.3 * np.sin(4 * s), np.zeros_like(s)])
    dead_reckoning = np.column_stack([-3.0 + 13.0 * s, 2.5 * s, np.zeros_like(s)])  # ends at x = 10 m (edge: 4 m)
    zones = [(f"z{i}", x, y, 0.6) for i, (x, y) in enumerate([(-3, -2.2), (-3, 2.2), (3, -2.2), (3, 2.2), (0, 2.2),
                                                               (0, -2.2), (1.0, 0.5)])]  # fmt: skip
    paths = {"truth": truth, "dead_reckoning": dead_reckoning}
    fig = plot_paths(terrain, paths, path, keep_out=zones)
    _png_ok(path)
    fig.canvas.draw()
    return fig, paths, zones


def test_map_legend_is_off_the_hazards(tmp_path: Path, terrain: Terrain) -> None:
    fig, _, zones = _map_with_hazards(terrain, tmp_path / "p.png")
    (ax,) = fig.axes
    legend = ax.get_legend().get_window_extent()
    circles = [p.get_window_extent() for p in ax.patches if isinstance(p, Circle)]
    assert len(circles) == len(zones)
    assert not any(_overlap(legend, c) for c in circles)
    rocks = [c.get_window_extent() for c in ax.collections if isinstance(c, PolyCollection)]
    assert rocks and not any(_overlap(legend, r) for r in rocks)


def test_map_holds_every_path(tmp_path: Path, terrain: Terrain) -> None:
    fig, paths, _ = _map_with_hazards(terrain, tmp_path / "p.png")
    (ax,) = fig.axes
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    for name, p in paths.items():
        inside = (p[:, 0] > x0) & (p[:, 0] < x1) & (p[:, 1] > y0) & (p[:, 1] < y1)
        assert inside.all(), f"{name} leaves the map ({x0:.1f}..{x1:.1f}, {y0:.1f}..{y1:.1f})"


def _fake_run(terrain: Terrain):  # noqa: ANN202
    """A finished run's parts as write_outputs reads them: VO steps of 0.35 m and one of 2 cm commanded travel in
    which the rover slid back 10 cm (slip 600 %: a ratio over almost no commanded travel)."""
    from types import SimpleNamespace

    from nav.geometry import se3
    from nav.trajectory import Pose
    from rover_sim.runtime.evaluator import Evaluator
    from rover_sim.scenario.loading import scenario_from_dict

    sc = scenario_from_dict({"name": "plotted", "seed": 7, "sensors": {"profile": "ideal"},
                             "commands": [{"type": "drive", "distance_m": 1.0}],
                             "keep_out": [{"name": "rock", "x_m": 1.0, "y_m": 0.5, "radius_m": 0.8}]})  # fmt: skip
    ev = Evaluator(sc.name, sc.seed, None, has_vo=True)
    x_m, commanded_m = -2.0, 0.0
    for k, (cmd_m, true_m) in enumerate([(0.0, 0.0), (0.35, 0.30), (0.35, 0.25), (0.02, -0.10), (0.35, 0.33)]):
        x_m, commanded_m = x_m + true_m, commanded_m + cmd_m
        truth = Pose(float(k), np.array([x_m, 0.0, 0.0]), np.array([1.0, 0.0, 0.0, 0.0]))
        ev.record(truth, truth, truth, commanded_m)
        motion = se3(np.eye(3), np.array([true_m + 0.01, 0.0, 0.0]))
        ev.vo_step(truth, "first_frame" if k == 0 else "ok", motion, cmd_m, 50, 1.0)
    metrics = ev.metrics(wall_s=1.0, sim_s=4.0, halted=None, extra={}, timing={})
    mission = SimpleNamespace(sc=sc, sim=SimpleNamespace(deform=None), terrain=terrain, events=["done"],
                              trajectories=ev.trajectories, vo_steps=ev.vo_steps)  # fmt: skip
    return mission, metrics


def _write_run_plots(tmp_path: Path, terrain: Terrain, monkeypatch):  # noqa: ANN202
    """write_outputs of the fake run; the figures it drew, by plotting function."""
    from rover_sim.io import plots
    from rover_sim.runtime.run import write_outputs

    figures = {}
    for name in ("plot_error_vs_distance", "plot_paths", "plot_slip"):

        def keep(*args, _f=getattr(plots, name), _name=name, **kw):  # noqa: ANN002, ANN003, ANN202
            figures[_name] = fig = _f(*args, **kw)
            return fig

        monkeypatch.setattr(plots, name, keep)
    mission, metrics = _fake_run(terrain)
    write_outputs(mission, metrics, tmp_path)
    for png in ("error_vs_distance.png", "paths.png", "slip.png"):
        _png_ok(tmp_path / "plots" / png)
    assert set(figures) == {"plot_error_vs_distance", "plot_paths", "plot_slip"}
    return figures, metrics


def test_slip_plot_agrees_with_metrics(tmp_path: Path, terrain: Terrain, monkeypatch) -> None:
    figures, metrics = _write_run_plots(tmp_path, terrain, monkeypatch)
    lines = [np.asarray(ln.get_ydata(), float) for ln in figures["plot_slip"].axes[0].get_lines()]
    truth, vo = lines[0], lines[1]  # drawn in this order; then the zero line
    assert metrics.max_slip_pct == pytest.approx(28.57, abs=0.01)  # the 0.25 m of a 0.35 m step; not the 600 %
    assert np.nanmax(truth) == pytest.approx(metrics.max_slip_pct, abs=0.01)
    assert np.nanmax(vo) == pytest.approx(metrics.max_vo_slip_pct, abs=0.01)


def test_run_plots_name_the_scenario_seed_and_profile(tmp_path: Path, terrain: Terrain, monkeypatch) -> None:
    figures, _ = _write_run_plots(tmp_path, terrain, monkeypatch)
    for fig in figures.values():
        title = fig.axes[0].get_title()
        assert all(w in title for w in ("plotted", "seed 7", "ideal")), title
