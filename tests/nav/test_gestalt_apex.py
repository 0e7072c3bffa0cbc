"""GESTALT's apex correction (nav.gestalt.map.apex_lift_m): a cone whose top stereo smoothed away is still a hazard.

Hazcam stereo at 256^2 matches 9 x 9 px windows, so the surface it returns is the true one averaged over the
window's footprint, half a window (4.5 px of a 69.4 px focal length) to each side: a narrow apex comes out low.
The synthetic clouds below are made that way: flat ground with 1 cm noise and one rock 2.2 m from the rover,
its heights averaged over a disc of radius 0.065 rad x 2.2 m, the ground behind it in its shadow. A 27 cm cone then
tops out at about 18-19 cm (bench autonav's fields: cones of 25-30 cm mapped 8-13 cm low).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.ndimage import convolve

from nav.gestalt import GestaltParams, GoodnessMap, apex_lift_m

P = GestaltParams()
OLD = replace(P, apex_reach_rad=None)  # the map without the correction
ROVER_XY = np.zeros(2)
ROCK_XY = (2.2, 0.0)
WINDOW_HALF_RAD = 4.5 / 69.4  # half the SAD window over the hazcam focal length (px / px)
GRID_M = 0.01


def seen_by_stereo(shape: str, height_m: float, radius_m: float, seed: int) -> np.ndarray:
    """(N, 3) range points of flat ground with one rock at ROCK_XY, low-passed by the matching window."""
    half = radius_m + 0.3  # the rock and its smoothed rim, on a local grid (flat ground elsewhere)
    xs = np.arange(-half, half, GRID_M)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    r = np.hypot(gx, gy) / radius_m
    z = height_m * (np.clip(1.0 - r, 0.0, None) if shape == "cone" else np.sqrt(np.clip(1.0 - r * r, 0.0, None)))
    reach_m = WINDOW_HALF_RAD * np.hypot(*ROCK_XY)
    o = np.arange(-int(round(reach_m / GRID_M)), int(round(reach_m / GRID_M)) + 1) * GRID_M
    disc = (np.hypot(*np.meshgrid(o, o, indexing="ij")) <= reach_m).astype(float)
    z = convolve(z, disc / disc.sum(), mode="constant")
    rng = np.random.default_rng(seed)
    n = 600 * 64
    x, y = rng.uniform(-4.0, 4.0, n), rng.uniform(-4.0, 4.0, n)
    i, j = (
        np.floor((x - ROCK_XY[0] + half) / GRID_M).astype(int),
        np.floor((y - ROCK_XY[1] + half) / GRID_M).astype(int),
    )
    on_grid = (i >= 0) & (i < len(xs)) & (j >= 0) & (j < len(xs))
    zs = np.where(on_grid, z[i.clip(0, len(xs) - 1), j.clip(0, len(xs) - 1)], 0.0)
    behind = (x > ROCK_XY[0]) & (x < ROCK_XY[0] + 0.8) & (np.abs(y - ROCK_XY[1]) < radius_m)
    shadow = behind & (np.hypot(x - ROCK_XY[0], y - ROCK_XY[1]) >= radius_m)
    return np.stack([x, y, zs + rng.normal(0.0, 0.01, n)], axis=1)[~shadow]


def worst_goodness_at_rock(params: GestaltParams, pts: np.ndarray, radius_m: float) -> float:
    gmap = GoodnessMap(params)
    gmap.update(pts, ROVER_XY)
    w = gmap.evaluate(ROVER_XY)
    c = w.cell_centres_xy()
    near = np.hypot(c[..., 0] - ROCK_XY[0], c[..., 1] - ROCK_XY[1]) <= radius_m
    return float(np.nanmin(w.goodness[near]))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_27cm_cone_read_low_is_passable_without_the_correction_and_a_hazard_with_it(seed: int) -> None:
    pts = seen_by_stereo("cone", 0.27, 0.27, seed)
    on_rock = np.hypot(pts[:, 0] - ROCK_XY[0], pts[:, 1] - ROCK_XY[1]) < 0.27
    assert pts[on_rock, 2].max() < 0.20  # the apex reads 7+ cm low
    assert worst_goodness_at_rock(OLD, pts, 0.27) > 0.05  # the old map: poor, but passable
    assert worst_goodness_at_rock(P, pts, 0.27) == 0.0  # with the correction: impassable


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_12cm_dome_stays_passable(seed: int) -> None:
    assert worst_goodness_at_rock(P, seen_by_stereo("dome", 0.12, 0.25, seed), 0.25) > 0.2


def test_clean_planes_gain_nothing() -> None:
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-3, 3, 20000), rng.uniform(-3, 3, 20000)
    gmap = GoodnessMap(P)
    gmap.update(np.stack([x, y, 0.2 * x - 0.1 * y], axis=1), ROVER_XY)
    w = gmap.evaluate(ROVER_XY)
    assert np.nanmax(w.step_m) < 1e-9  # no cell of a clean plane with >= 4 known neighbours is a peak
    assert apex_lift_m(np.zeros((6, 3, 3)), np.ones((3, 3)), OLD) is None


def test_the_lift_is_the_median_flank_slope_times_the_window_reach() -> None:
    """One cell 0.1 m above its eight neighbours, seen from 2 m: the median of the 4 edge and 4 diagonal slopes
    times apex_reach_rad x 2 m; no other cell is raised."""
    extremes = np.zeros((6, 5, 5))
    extremes[3, 2, 2] = 0.1
    lift = apex_lift_m(extremes, np.full((5, 5), 2.0), P)
    slope = 0.5 * (0.1 / (P.cell_size_m * np.sqrt(2.0)) + 0.1 / P.cell_size_m)
    assert lift is not None and lift[2, 2] == pytest.approx(slope * P.apex_reach_rad * 2.0, abs=1e-12)
    assert np.count_nonzero(lift) == 1
