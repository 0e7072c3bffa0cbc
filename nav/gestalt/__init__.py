"""GESTALT obstacle avoidance: goodness map, steering-arc votes, arbiter (Maimone et al. 2005, section 4.2).

"Range images from stereo are converted to goodness or traversability maps with 20 cm cells in a 10x10 m grid
centered on the rover. [...] planar patches centered on each map cell [...] each patch is a circle with the diameter
of the rover. The surface normal, RMS residual, and minimum and maximum elevation difference from the best fit plane
determine a goodness factor [...] Goodness maps [...] are registered and accumulated over time with the usual modulo
map indexing [...] new data overwrites the old [...] 23 forward arcs, 23 backward arcs, and two point turns [...]
adding up the goodness scores along each arc, with nearby cells given higher weight. [...] an arbiter, which also
takes input from waypoints."

One cycle, :meth:`GestaltPlanner.step`, reads as the paper's steps:

1. :meth:`GoodnessMap.update` - bin the world-frame range points into a world-fixed toroidal grid of per-cell point
   statistics (count, first and second moments, trimmed min/max elevation); cells seen in this image replace what
   was there, unless the old look was taken from much nearer (or held far more points): hazcam stereo error grows
   with range squared, and a rock at the edge of the view must not be erased by a glimpse of its flank.
2. :meth:`GoodnessMap.evaluate` - per cell of the 10 m window around the rover: least-squares plane through the
   points within ``patch_radius_m`` (summed moments of the neighbouring cells, one convolution per moment), giving
   tilt, RMS roughness and the step (spread of the min/max elevations about the plane); goodness 1 on benign ground
   falling linearly to 0 at any limit.
3. :func:`vote_arcs` - traversability vote per arc: weighted mean goodness over the rover's footprint (a rectangle)
   swept along the arc, nearer cells weighted more; an unknown or impassable cell met by the footprint's core
   within ``near_distance_m`` vetoes the arc; the lowest goodness the core meets is kept for the arbiter.
4. :func:`cost_to_go`, :func:`waypoint_votes` and :func:`arbitrate` - the goal's vote, then the best weighted sum of
   safe arcs, or none. The waypoint input is a path-cost field to the goal over the goodness window (Dijkstra;
   the MER flight software gained such a field in 2006, Carsten et al. 2007), so that an arc making progress along
   a detour round a rock outvotes one pointing straight at the goal behind it; near the goal the arc through the
   goal itself is driven (:func:`goal_arc`). Against dithering (GESTALT's classic failure: left-right-left, or
   forward-back-forward in front of a gap it cannot quite take) the arbiter penalises taking back the previous
   move (:func:`undoes`), the path walls off gaps narrower than the arcs can thread, and every cycle the rover
   stands somewhere makes the path there dearer (``GestaltPlanner.visits``).

Frames: world x east, y north, z up; poses are ``(x_m, y_m, yaw_rad)`` in the world, yaw about +z from +x. Arcs are
defined in the rover frame (x forward, y left). Pure: no drawing or logging; every result is returned as data.

Footprint sizes (see :class:`GestaltParams`): the paper's plane-fit patch is the whole rover (2.6 m diameter), which
grows every obstacle by the rover's radius, so arcs can be judged along their centre line. Here the patch is smaller
(0.6 m radius: about the wheel track's half-width, the wheels of a rover centred on the cell) so tilt and roughness
describe the ground under the wheels rather than a 5 m^2 average. Stereo at 256^2 reads rocks low (the SAD window
smooths their tops), so a rock is impassable only where the patch reaches its upper part: in practice goodness
grows a rock by ~0.35 m beyond its edge, not by the full patch radius. Vetoes therefore look at a core rectangle
(0.45 m x 0.4 m half-sizes) carried along the arc: the wheels' envelope plus a margin, less that growth; turning in
place, the core's corners sweep a disc. Votes average over the full footprint, so arcs passing obstacles with a
margin score better.

Modules, in the order of the steps: :mod:`nav.gestalt.params` (thresholds), :mod:`nav.gestalt.map` (steps 1-2,
goodness map), :mod:`nav.gestalt.arcs` (the arcs and their traversability votes, step 3),
:mod:`nav.gestalt.path_cost` (the path-cost field behind the waypoint votes, step 4a), :mod:`nav.gestalt.arbiter`
(waypoint votes, arbiter and one whole cycle, step 4).
"""

from nav.gestalt.arbiter import Decision, GestaltPlanner, arbitrate, undoes, waypoint_votes
from nav.gestalt.arcs import Arc, ArcVotes, arc_pose, arcs, closest_approach, goal_arc, vote_arcs
from nav.gestalt.map import GoodnessMap, GoodnessWindow, apex_lift_m, fit_patch_planes, goodness_from, patch_step_m
from nav.gestalt.params import GestaltParams
from nav.gestalt.path_cost import CostToGo, cost_to_go

__all__ = [
    "Arc",
    "ArcVotes",
    "CostToGo",
    "Decision",
    "GestaltParams",
    "GestaltPlanner",
    "GoodnessMap",
    "GoodnessWindow",
    "arbitrate",
    "arc_pose",
    "apex_lift_m",
    "arcs",
    "closest_approach",
    "cost_to_go",
    "fit_patch_planes",
    "goal_arc",
    "goodness_from",
    "patch_step_m",
    "undoes",
    "vote_arcs",
    "waypoint_votes",
]
