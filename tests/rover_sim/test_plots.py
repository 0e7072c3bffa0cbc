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
