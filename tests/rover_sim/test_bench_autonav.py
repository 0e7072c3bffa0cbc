"""The autonav benchmark's fields are as specified: 10 % rock cover, rocks up to 60 cm, goal 20 m away,
with rocks the rover must not touch (>= 25 cm) in its way; and the loop drives on its own pose with VO on."""

from __future__ import annotations

import numpy as np
import pytest

from rover_sim.bench.autonav import GOAL_DISTANCE_M, field_scenario
from rover_sim.runtime.acceptance import TALL_ROCK_M
from rover_sim.scenario.loading import scenario_from_dict
from terrains import synthesize
from terrains.golombek import cumulative_area_fraction


@pytest.mark.parametrize("seed", [0, 7])
def test_fields_hold_the_rock_population_the_issue_names(seed: int) -> None:
    sc = scenario_from_dict(field_scenario(seed))
    terrain = synthesize(sc.terrain, sc.seed)
    rocks = terrain.rocks
    heights = np.array([r.height_m for r in rocks])
    assert heights.max() <= 0.6 + 1e-9
    sx, sy = sc.terrain.size_m
    cover = sum(np.pi / 4 * r.length_m * r.width_m for r in rocks) / (sx * sy)
    spec = sc.terrain.rocks
    assert spec.cover_fraction == pytest.approx(0.10)
    # k = 0.10 counts every rock; those under min_height_m are left to the roughness, so the geoms cover
    # k exp(-q D_min) of the ground (Golombek-Rapp), give or take sampling noise and the start/goal clearings
    expected = float(cumulative_area_fraction(spec.min_diameter_m, spec.cover_fraction))
    assert cover == pytest.approx(expected, rel=0.3)
    start, goal = np.array([sc.start.x_m, sc.start.y_m]), np.array([sc.commands[0].x_m, sc.commands[0].y_m])
    assert np.linalg.norm(goal - start) == pytest.approx(GOAL_DISTANCE_M)
    # tall rocks across the straight line's corridor (the rover's width plus a margin): the goal is not a free run
    xy = np.array([[r.x_m, r.y_m] for r in rocks])
    in_way = (np.abs(xy[:, 1] - start[1]) < 1.5) & (xy[:, 0] > start[0] + 1.5) & (xy[:, 0] < goal[0] - 1.2)
    assert (in_way & (heights >= TALL_ROCK_M)).sum() >= 3


def test_fields_drive_on_the_onboard_pose_with_navcam_vo() -> None:
    sc = scenario_from_dict(field_scenario(3))
    assert sc.nav.vo.enabled and sc.nav.camera == "navcam"
    assert sc.commands[0].type == "autonav"
