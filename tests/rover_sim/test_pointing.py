"""Texture-seeking mast pointing keeps the mast near its commanded pointing (rover_sim/mission/pointing.py)."""

from __future__ import annotations

from rover_sim.mission.pointing import (
    POOR_VIEW_FEATURES,
    PointingCandidate,
    choose_pointing,
    step_toward_home,
)

HOME = (0.0, -40.0)


def test_among_good_views_the_one_nearest_home_wins_not_the_richest() -> None:
    far_rich = PointingCandidate(0.0, -48.0, 300, 0.9)
    home = PointingCandidate(0.0, -40.0, POOR_VIEW_FEATURES, 0.7)
    assert choose_pointing([far_rich, home], HOME) == home


def test_when_every_view_is_poor_the_richest_wins_and_ties_go_home() -> None:
    a = PointingCandidate(0.0, -56.0, 30, 0.8)
    b = PointingCandidate(0.0, -48.0, 30, 0.8)
    c = PointingCandidate(12.0, -56.0, 12, 0.8)
    assert choose_pointing([a, c, b], HOME) == b
    assert choose_pointing([a, c], HOME) == a


def test_a_view_without_overlap_is_never_chosen() -> None:
    rich_no_overlap = PointingCandidate(0.0, -40.0, 500, 0.3)
    poor = PointingCandidate(12.0, -40.0, 5, 0.61)
    assert choose_pointing([rich_no_overlap, poor], HOME) == poor
    assert choose_pointing([rich_no_overlap], HOME) is None


def test_the_step_home_is_one_candidate_step_per_axis_and_stops_there() -> None:
    assert step_toward_home(24.0, -64.0, HOME) == (12.0, -56.0)
    assert step_toward_home(-5.0, -44.0, HOME) == (0.0, -40.0)
    assert step_toward_home(*HOME, HOME) == HOME
