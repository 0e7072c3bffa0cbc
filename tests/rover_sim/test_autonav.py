"""GESTALT autonav in the closed loop on a small field: around a tall rock to the goal, never touching it."""

from __future__ import annotations

import numpy as np
import pytest

from rover_sim.runtime.acceptance import TALL_ROCK_M
from rover_sim.runtime.onboard import SELF_MASK_HALF_LENGTH_M, SELF_MASK_HALF_WIDTH_M, terrain_points
from rover_sim.runtime.runner import Mission
from rover_sim.scenario.loading import scenario_from_dict

START_X, GOAL_X = -2.5, 2.5
BLOCK = {"name": "block", "x_m": 0.0, "y_m": 0.15, "length_m": 0.8, "width_m": 0.7, "height_m": 0.40, "yaw_deg": 15}

ROCK_ON_THE_WAY = {
    "name": "autonav_rock_on_the_way",
    "seed": 7,
    "terrain": {
        "size_m": [10, 7],
        "cell_size_m": 0.05,
        "roughness": {"rms_m": 0.01, "correlation_length_m": 1.5},
        "rocks": {"cover_fraction": 0.0},
        "explicit_rocks": [BLOCK],
        "material": {"kind": "bedrock"},
    },
    "start": {"x_m": START_X, "y_m": 0.0, "yaw_deg": 0},
    "nav": {"vo": False, "camera": "hazcam_front", "image_noise": True},
    "commands": [{"type": "autonav", "x_m": GOAL_X, "y_m": 0.0, "tolerance_m": 0.4, "max_cycles": 24}],
    "pass": {"goal_within_m": 1.0, "max_body_collisions": 0},
}


@pytest.fixture(scope="module")
def rock_run():
    mission = Mission(scenario_from_dict(ROCK_ON_THE_WAY))
    try:
        metrics = mission.run()
    finally:
        mission.close()
    return mission, metrics


def test_reaches_the_goal_around_the_rock_without_touching_it(rock_run) -> None:
    mission, m = rock_run
    stats = mission.autonav_stats
    assert stats.outcome.startswith("goal reached"), mission.events[-5:]
    assert m.goal_distance_m is not None and m.goal_distance_m < 1.0
    assert m.tall_rock_contacts == 0 and m.body_collisions == 0
    assert m.passed, m.reason
    xy = mission.trajectories()["truth"].positions_xyz[:, :2]
    # it went round: where it passed the rock it was well to one side of it
    beside = np.abs(xy[:, 0] - BLOCK["x_m"]) < 0.3
    assert beside.any() and np.abs(xy[beside, 1] - BLOCK["y_m"]).min() > 0.4 + 0.55
    assert stats.cycles <= 20  # no dithering in front of it
    assert all(ms > 0 for ms in stats.cycle_ms)


def test_the_rock_is_an_obstacle_in_the_first_map(rock_run) -> None:
    mission, _ = rock_run
    first = mission.autonav_stats  # the last decision's window still remembers the rock if it is near
    w = first.last_decision.window
    i, j, inside = w.cell_index(np.array([[BLOCK["x_m"], BLOCK["y_m"]]]))
    if inside[0]:
        assert w.goodness[i[0], j[0]] == 0.0 or np.isnan(w.goodness[i[0], j[0]])
    assert TALL_ROCK_M == 0.25


def test_terrain_points_drop_the_rover_and_far_points() -> None:
    pts = np.array(
        [
            [0.6, 0.55, -0.3],  # the left front wheel
            [-0.5, -0.5, -0.4],  # under the body
            [1.5, 0.0, -0.5],  # ground ahead
            [0.5, 1.2, -0.5],  # ground beside the rover
            [8.0, 0.0, -0.5],  # too far for hazcam stereo
        ]
    )
    kept = terrain_points(pts)
    np.testing.assert_array_equal(kept, pts[[2, 3]])
    assert SELF_MASK_HALF_LENGTH_M > 0.55 + 0.125 and SELF_MASK_HALF_WIDTH_M > 0.55 + 0.08
