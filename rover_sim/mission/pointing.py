"""Texture-seeking mast pointing before a VO step (issue #17, item 2), as MER's drivers pointed the navcams at
textured ground (rocks, outcrop edges, the rover's own tracks) for VO.

Before each VO pair :func:`seek_texture` asks the onboard stack how many trackable features of the previous pair
the planned view will see (after the dead-reckoned motion). If fewer than ``POOR_VIEW_FEATURES``, it looks at the
nearby pointings (``CANDIDATES_DEG`` around the current one, within ``MAX_OFFSET_DEG`` of the commanded pointing):
for each one that keeps >= 60 % ground overlap with the previous pair (:data:`nav.vo.texture.MIN_OVERLAP`) it
images a pair and counts the trackable features in the overlap, and keeps the best; the choice is logged as an
event and counted (``pointing_changes``). When no pointing has enough texture for VO (``min_features``), the
step is logged as a justified refusal: VO then declines on it, and the evaluator counts it as justified.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from nav.vo.texture import MIN_OVERLAP

if TYPE_CHECKING:
    from rover_sim.mission.pipeline import Mission

POOR_VIEW_FEATURES = 60  # the planned view is poor below this many trackable features (3x VO's min_features)
CANDIDATES_DEG = ((0.0, 0.0), (12.0, 0.0), (-12.0, 0.0), (0.0, 8.0), (0.0, -8.0))  # (pan, elevation) offsets
MAX_OFFSET_DEG = 30.0  # stay within this of the scenario's commanded pointing
SETTLE_S = 1.0  # a small mast move settles within a second


def seek_texture(mission: Mission) -> bool:
    """Repoint the mast if the planned view is predicted poor. Returns True if no pointing had texture."""
    ob, world, sc = mission.onboard, mission.world, mission.sc
    camera = sc.nav.camera
    if camera != "navcam":
        return False
    planned = ob.planned_view_texture(world.onboard_rig(camera))
    if planned is None or planned >= POOR_VIEW_FEATURES:
        return False
    pan0, el0 = world.mast_pan_deg, world.mast_elevation_deg
    best: tuple[int, float, float, float] | None = None  # (features, overlap, pan, elevation)
    for dpan, del_ in CANDIDATES_DEG:
        pan, el = pan0 + dpan, el0 + del_
        if abs(pan - sc.nav.mast_pan_deg) > MAX_OFFSET_DEG or abs(el - sc.nav.mast_tilt_deg) > MAX_OFFSET_DEG:
            continue
        if (dpan, del_) != (0.0, 0.0) or (world.mast_pan_deg, world.mast_elevation_deg) != (pan, el):
            mission.point_mast(pan, el, settle_s=SETTLE_S)
        world.calibrate(camera)
        obs = world.observation_with([], [], {camera: world.render(camera)})
        n, overlap = ob.candidate_texture(obs, camera)
        if overlap >= MIN_OVERLAP and (best is None or n > best[0]):
            best = (n, overlap, pan, el)
    n, overlap, pan, el = best if best is not None else (0, 0.0, pan0, el0)
    if (world.mast_pan_deg, world.mast_elevation_deg) != (pan, el):
        mission.point_mast(pan, el, settle_s=SETTLE_S)
    world.calibrate(camera)
    if (pan, el) != (pan0, el0):
        mission.pointing_changes += 1
        mission.event(
            f"texture-seeking pointing: planned view {planned} trackable features; mast to pan {pan:.0f}, "
            f"elevation {el:.0f} deg ({n} features, {100 * overlap:.0f} % overlap)"
        )
    if n < ob.texture_params.min_features:
        mission.event(
            f"no pointing had texture: best {n} trackable features (< {ob.texture_params.min_features}) among "
            f"{len(CANDIDATES_DEG)} pointings with >= {100 * MIN_OVERLAP:.0f} % overlap; VO refusal justified",
            "WARN",
        )
        return True
    return False
