"""Texture-seeking mast pointing before a VO step, as MER's drivers pointed the navcams at
textured ground (rocks, outcrop edges, the rover's own tracks) for VO.

Before each VO pair :func:`seek_texture` asks the onboard stack how many trackable features of the previous pair
the planned view will see (after the dead-reckoned motion). If fewer than ``POOR_VIEW_FEATURES``, it looks at the
nearby pointings (``CANDIDATES_DEG`` around the current one, within ``MAX_PAN_OFFSET_DEG`` and
``MAX_ELEVATION_OFFSET_DEG`` of the commanded pointing):
for each one that keeps >= 60 % ground overlap with the previous pair (:data:`nav.vo.texture.MIN_OVERLAP`) it
images a pair and counts the trackable features in the overlap. The choice is logged as an event and counted
(``pointing_changes``). When no pointing has enough texture for VO (``min_features``), the step is logged as a
justified refusal: VO then declines on it, and the evaluator counts it as justified.

The commanded pointing is home (:func:`choose_pointing`). The operators chose it for the drive's geometry, and the
views far from it are poor: pointed steeply down (elevation -64 deg against the commanded -40) the navcam sees the
ground within a metre of the rover, where a 0.5 m step leaves 7-30 trackable features against 80-120 at -40 deg
(measured in ``bench autonav`` fields 3, 8 and 14, flight profile). Picking the candidate with the most features
each time made the mast ratchet away from home one step at a time (-40, -48, -56, -64 deg, then it stayed) and
VO starve until its consecutive-failure limit stopped the drive. The count is of features inside the previous
pair's view, so it favours the pointing the previous pair was taken from and cannot by itself lead back. So:
elevation stays within one step (8 deg) of the commanded one, pan within 30 deg; among the candidates with enough
texture (``POOR_VIEW_FEATURES``) the one nearest home wins; while off home with a good view, one step back toward
home is tried before each pair; and when the step is lost anyway (no candidate keeps the overlap, or none has
VO's ``min_features``) the pair is imaged from home, so that the next steps start from the commanded view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from nav.vo.texture import MIN_OVERLAP

if TYPE_CHECKING:
    from rover_sim.runtime.onboard import Onboard
    from rover_sim.scenario.schema import Scenario
    from rover_sim.world.world import World

POOR_VIEW_FEATURES = 60  # the planned view is poor below this many trackable features (3x VO's min_features)
CANDIDATES_DEG = ((0.0, 0.0), (12.0, 0.0), (-12.0, 0.0), (0.0, 8.0), (0.0, -8.0))  # (pan, elevation) offsets
PAN_STEP_DEG, ELEVATION_STEP_DEG = 12.0, 8.0  # one step back toward home, at most (the candidates' spacing)
MAX_PAN_OFFSET_DEG = 30.0  # stay within this of the scenario's commanded pan
MAX_ELEVATION_OFFSET_DEG = 8.0  # and within one candidate step of its elevation (the footprint's range)
SETTLE_S = 1.0  # a small mast move settles within a second


class PointingRunner(Protocol):
    """What texture seeking uses of the runner (:class:`rover_sim.runtime.runner.Mission` is one)."""

    sc: Scenario
    world: World
    onboard: Onboard
    pointing_changes: int

    def point_mast(self, pan_deg: float, elevation_deg: float, settle_s: float = ...) -> None: ...

    def event(self, text: str, level: str = "INFO") -> None: ...


@dataclass(frozen=True)
class PointingCandidate:
    """One imaged mast pointing: its trackable features inside the previous pair's view and the ground overlap."""

    pan_deg: float
    elevation_deg: float
    features: int
    overlap: float


def offset_from_home_deg(pan_deg: float, elevation_deg: float, home: tuple[float, float]) -> float:
    """Angular distance of a pointing from home, in degrees of pan and elevation (a small-angle measure)."""
    return math.hypot(pan_deg - home[0], elevation_deg - home[1])


def step_toward_home(pan_deg: float, elevation_deg: float, home: tuple[float, float]) -> tuple[float, float]:
    """The pointing one candidate step (``PAN_STEP_DEG``, ``ELEVATION_STEP_DEG``) closer to home on each axis."""
    dpan = max(-PAN_STEP_DEG, min(PAN_STEP_DEG, home[0] - pan_deg))
    delev = max(-ELEVATION_STEP_DEG, min(ELEVATION_STEP_DEG, home[1] - elevation_deg))
    return pan_deg + dpan, elevation_deg + delev


def choose_pointing(
    candidates: list[PointingCandidate], home: tuple[float, float], enough_features: int = POOR_VIEW_FEATURES
) -> PointingCandidate | None:
    """The pointing to image the VO pair from; None when no candidate keeps ``MIN_OVERLAP`` with the previous pair.

    Among the candidates that keep the overlap, those with at least ``enough_features`` are all good for VO and the
    one nearest home wins (ties: more features); when none has enough, the one with the most features (ties:
    nearer home).
    """
    usable = [c for c in candidates if c.overlap >= MIN_OVERLAP]
    if not usable:
        return None
    good = [c for c in usable if c.features >= enough_features]
    if good:
        return min(good, key=lambda c: (offset_from_home_deg(c.pan_deg, c.elevation_deg, home), -c.features))
    return max(usable, key=lambda c: (c.features, -offset_from_home_deg(c.pan_deg, c.elevation_deg, home)))


def _image_candidate(mission: PointingRunner, pan_deg: float, elevation_deg: float) -> PointingCandidate:
    """Point the mast, image a pair and count its texture (the onboard stack's view of it)."""
    world, camera = mission.world, mission.sc.nav.camera
    _move_to(mission, pan_deg, elevation_deg)
    obs = world.observation_with([], [], {camera: world.render(camera)})
    n, overlap = mission.onboard.candidate_texture(obs, camera)
    return PointingCandidate(pan_deg, elevation_deg, n, overlap)


def _move_to(mission: PointingRunner, pan_deg: float, elevation_deg: float) -> None:
    """Point the mast there (if it is not already) and take the onboard calibration at that pointing."""
    world = mission.world
    if (world.mast_pan_deg, world.mast_elevation_deg) != (pan_deg, elevation_deg):
        mission.point_mast(pan_deg, elevation_deg, settle_s=SETTLE_S)
    world.calibrate(mission.sc.nav.camera)


def _return_home(mission: PointingRunner, home: tuple[float, float], pan0: float, el0: float) -> str:
    """Point the mast home for a step VO cannot use; counts the change and returns the event's note on it."""
    _move_to(mission, *home)
    if home == (pan0, el0):
        return ""
    mission.pointing_changes += 1
    return f"; mast back to the commanded pan {home[0]:.0f}, elevation {home[1]:.0f} deg"


def seek_texture(mission: PointingRunner) -> bool:
    """Repoint the mast if the planned view is predicted poor. Returns True if no pointing had texture."""
    ob, world, sc = mission.onboard, mission.world, mission.sc
    camera = sc.nav.camera
    if camera != "navcam":
        return False
    home = (sc.nav.mast_pan_deg, sc.nav.mast_tilt_deg)
    pan0, el0 = world.mast_pan_deg, world.mast_elevation_deg
    planned = ob.planned_view_texture(world.onboard_rig(camera))
    if planned is None:
        return False
    if planned >= POOR_VIEW_FEATURES:
        if (pan0, el0) == home:
            return False
        back = _image_candidate(mission, *step_toward_home(pan0, el0, home))
        if back.overlap >= MIN_OVERLAP and back.features >= POOR_VIEW_FEATURES:
            _log_change(mission, planned, back, "back toward the commanded pointing")
        else:
            _move_to(mission, pan0, el0)
        return False
    tried: list[PointingCandidate] = []
    for dpan, del_ in CANDIDATES_DEG:
        pan, el = pan0 + dpan, el0 + del_
        if abs(pan - home[0]) > MAX_PAN_OFFSET_DEG or abs(el - home[1]) > MAX_ELEVATION_OFFSET_DEG:
            continue
        tried.append(_image_candidate(mission, pan, el))
    best = choose_pointing(tried, home)
    if best is None:  # nothing keeps the overlap (a turn in place): VO cannot track, so restart it from home
        back = _return_home(mission, home, pan0, el0)
        mission.event(
            f"no pointing kept {100 * MIN_OVERLAP:.0f} % ground overlap with the previous pair ({len(tried)} tried)"
            f"{back} (VO cannot track across this step: it re-initialises, or a refusal is justified)",
            "WARN",
        )
        return True
    if best.features < ob.texture_params.min_features:  # VO will refuse this step: image it from home
        back = _return_home(mission, home, pan0, el0)
        mission.event(
            f"no pointing had texture: best {best.features} trackable features (< {ob.texture_params.min_features}) "
            f"among {sum(c.overlap >= MIN_OVERLAP for c in tried)} pointings with >= {100 * MIN_OVERLAP:.0f} % "
            f"overlap; VO refusal justified{back}",
            "WARN",
        )
        return True
    _move_to(mission, best.pan_deg, best.elevation_deg)
    if (best.pan_deg, best.elevation_deg) != (pan0, el0):
        _log_change(mission, planned, best, "")
    return False


def _log_change(mission: PointingRunner, planned: int, c: PointingCandidate, why: str) -> None:
    mission.pointing_changes += 1
    mission.event(
        f"texture-seeking pointing{': ' + why if why else ''}: planned view {planned} trackable features; mast to "
        f"pan {c.pan_deg:.0f}, elevation {c.elevation_deg:.0f} deg ({c.features} features, "
        f"{100 * c.overlap:.0f} % overlap)"
    )
