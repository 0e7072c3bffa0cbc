"""Texture-seeking mast pointing keeps the mast near its commanded pointing (rover_sim/runtime/pointing.py)."""

from __future__ import annotations

from types import SimpleNamespace

from rover_sim.runtime.pointing import (
    POOR_VIEW_FEATURES,
    PointingCandidate,
    choose_pointing,
    seek_texture,
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


class _FakeWorld:
    def __init__(self, pan_deg: float, elevation_deg: float) -> None:
        self.mast_pan_deg, self.mast_elevation_deg = pan_deg, elevation_deg

    def point_mast(self, pan_deg: float, elevation_deg: float) -> None:
        self.mast_pan_deg, self.mast_elevation_deg = pan_deg, elevation_deg

    def onboard_rig(self, camera: str) -> None:
        return None

    def calibrate(self, camera: str) -> None:
        pass

    def render(self, camera: str) -> tuple[float, float]:
        return (self.mast_pan_deg, self.mast_elevation_deg)

    def observation_with(self, _a: list, _b: list, frames: dict) -> tuple[float, float]:
        return frames["navcam"]


class _FakeOnboard:
    """Texture that grows the steeper the mast looks down (as the count inside the previous view did)."""

    def __init__(self, features_at, planned: int = 50) -> None:
        self.features_at, self.planned = features_at, planned
        self.texture_params = SimpleNamespace(min_features=20)

    def planned_view_texture(self, rig: None) -> int:
        return self.planned

    def candidate_texture(self, pointing: tuple[float, float], camera: str) -> tuple[int, float]:
        return self.features_at(*pointing), 0.7


class _FakeMission:
    def __init__(self, onboard: _FakeOnboard, home=HOME) -> None:
        self.world, self.onboard = _FakeWorld(*home), onboard
        self.sc = SimpleNamespace(nav=SimpleNamespace(camera="navcam", mast_pan_deg=home[0], mast_tilt_deg=home[1]))
        self.pointing_changes, self.events = 0, []

    def point_mast(self, pan_deg: float, elevation_deg: float, settle_s: float) -> None:
        self.world.point_mast(pan_deg, elevation_deg)

    def event(self, text: str, level: str = "INFO") -> None:
        self.events.append(text)


def test_poor_views_do_not_ratchet_the_mast_down() -> None:
    """Each step's richest view is one step lower; the mast must stay within one step of the commanded elevation
    (before, it walked -40, -48, -56, -64 and VO starved there)."""
    mission = _FakeMission(_FakeOnboard(lambda pan, el: int(30 - el - 40)))
    for _ in range(6):
        assert seek_texture(mission) is False
    assert mission.world.mast_elevation_deg >= HOME[1] - 8.0
    assert abs(mission.world.mast_pan_deg - HOME[0]) <= 30.0


def test_a_step_without_texture_is_imaged_from_home_and_is_justified() -> None:
    mission = _FakeMission(_FakeOnboard(lambda pan, el: 5))
    mission.world.point_mast(24.0, -48.0)
    assert seek_texture(mission) is True
    assert (mission.world.mast_pan_deg, mission.world.mast_elevation_deg) == HOME
    assert "no pointing had texture" in mission.events[-1]


def test_with_a_good_view_off_home_the_mast_steps_back() -> None:
    mission = _FakeMission(_FakeOnboard(lambda pan, el: 100, planned=80))
    mission.world.point_mast(24.0, -48.0)
    assert seek_texture(mission) is False
    assert (mission.world.mast_pan_deg, mission.world.mast_elevation_deg) == (12.0, -40.0)
