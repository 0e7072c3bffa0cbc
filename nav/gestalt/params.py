"""GESTALT's thresholds (Maimone et al. 2005, section 4.2): goodness map, arcs, votes, waypoint input and
arbiter, all in :class:`GestaltParams`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GestaltParams:
    """Every GESTALT threshold, with units. Paper values are marked "paper"; the rest say why."""

    # --- goodness map ---
    cell_size_m: float = 0.20  # paper
    map_size_m: float = 10.0  # paper: 10 x 10 m window centred on the rover
    # Radius of the plane-fit patch around each cell. Paper: the rover's diameter (2.6 m), i.e. 1.3 m; here 0.6 m
    # because arcs are scored over the swept footprint as well (module docstring).
    patch_radius_m: float = 0.6
    # A cell's data is replaced by a newer look only if that look is no more than this much farther away than the
    # one it replaces (None: always replace, as the paper).
    keep_closer_slack_m: float | None = 0.5
    # ... and only if it holds at least this fraction of the old look's points (a rock at the edge of the view, or
    # half hidden, must not erase a full look at it); None: no such rule
    keep_denser_fraction: float | None = 0.3
    min_points_per_cell: int = 3  # a cell with fewer own points is unknown
    min_points_patch: int = 20  # ... as is one whose patch holds fewer points
    # A cell's extreme elevations (for the step) skip this fraction of its points at each end: stereo mismatches
    # are isolated points; a rock is many.
    extreme_trim_fraction: float = 0.1
    # Goodness falls linearly from 1 at the benign value to 0 at the limit, per factor; the cell takes the worst.
    benign_tilt_deg: float = 10.0  # slip grows with slope beyond ~10-15 deg on sand (REFERENCE 2)
    max_tilt_deg: float = 30.0  # MER's rated static stability (about 30 deg; 31 deg seen on Mars)
    benign_roughness_m: float = 0.02  # RMS residual about the patch plane: sensor noise and gravel
    max_roughness_m: float = 0.10
    # Spread of elevations about the plane (rocks, ledges, holes): on flat ground hazcam stereo (256^2, 10 cm
    # baseline, points to 3.5 m) gives ~5 cm with the trimmed extremes.
    benign_step_m: float = 0.10
    # About one wheel diameter (25 cm) is what MER could climb and the rocks the rover must not touch; stereo reads
    # a rock's top some centimetres low (the SAD window smooths it), so the limit sits below: rocks >= 25 cm seen
    # 1-2 m ahead read >= 0.28 m (10th percentile over five fields), 10-15 cm rocks <= 0.23 m (90th).
    max_step_m: float = 0.22
    # Stereo loses a rock's narrow top (map.apex_lift_m): a peak's top is raised by its flank slope times
    # apex_reach_rad x range. 0.065 rad is half the 9 px SAD window of the 256^2 hazcams (4.5 px / 69.4 px focal
    # length), from the stereo's geometry, not tuned; 0 or None turns the correction off. The slope is capped at 1.5
    # (56 deg: steeper flanks are stereo noise at a depth edge, not rock).
    apex_reach_rad: float | None = 0.065
    apex_max_slope: float = 1.5

    # --- arcs ---
    n_forward_arcs: int = 23  # paper
    n_backward_arcs: int = 23  # paper
    max_curvature_per_m: float = 1.0  # tightest arc: 1 m radius (sharper turns are point turns)
    point_turn_deg: float = 45.0  # heading change of each of the two point turns (left, right)
    look_ahead_m: float = 3.0  # arc length scored; the rover re-plans after step_distance_m anyway
    step_distance_m: float = 0.5  # distance driven along the winning arc per cycle (paper: 35 cm to 1 m)
    capture_distance_m: float = 1.5  # goal this close and ahead: drive the arc through it, all the way
    min_drive_m: float = 0.35  # shortest drive per cycle (paper: 35 cm)
    # The footprint the votes average over, a rectangle carried along each arc: the wheels' envelope (outer edges
    # 0.63 m to the side: track 1.1 m, wheels 0.16 m wide; 0.68 m ahead and behind) plus ~0.2 m ...
    rover_half_width_m: float = 0.8
    rover_half_length_m: float = 0.85
    # ... and the core that decides vetoes: the wheels' envelope plus ~0.1 m, less the ~0.35 m by which goodness
    # already grows a rock beyond its edge (the patch radius, less the rock's low rim that stereo reads as ground)
    core_half_width_m: float = 0.4
    core_half_length_m: float = 0.45

    # --- votes ---
    near_distance_m: float = 1.5  # unknown or impassable cells this close along an arc veto it (3 cycles' drive)
    # The ground under the rover is not in its cameras' view but it is standing on it: unknown cells this close to
    # the rover's centre count as benign.
    assume_safe_radius_m: float = 1.0
    impassable_goodness: float = 0.0  # cells at or below this goodness are impassable
    unknown_goodness: float = 0.5  # goodness of an unknown cell beyond the near part
    weight_decay_m: float = 1.5  # cell weight exp(-s / decay), s the arc length at which the footprint reaches it
    # --- waypoint vote and arbiter ---
    # path cost to the goal (see cost_to_go): per metre, 1 on benign ground, 1 + goodness_cost on the worst
    # passable, unknown_cost on unseen ground
    goodness_cost: float = 2.0
    # ... plus up to doubt_cost below doubt_goodness: stereo reads rocks low, so a cell just short of impassable may
    # hide a rock over the limit; go round such cells where there is a way
    doubt_goodness: float = 0.4
    doubt_cost: float = 3.0
    unknown_cost: float = 1.3
    # impassable cells seen from farther than certain_range_m cost far_obstacle_cost per metre instead of being walls
    certain_range_m: float = 2.5
    far_obstacle_cost: float = 6.0
    # ... plus up to clearance_cost per metre closer than clearance_range_m to a wall (falling linearly to 0 there)
    clearance_cost: float = 2.0
    clearance_range_m: float = 0.8
    # walls are grown by core_half_width_m plus this for the path: a gap only a perfectly aligned rover could thread
    # (single arcs, the core's corners swinging on a turn) is closed to the path, rather than dithered in front of
    path_margin_m: float = 0.2
    # each cycle the rover has stood within visit_radius_m of a cell adds visit_cost per metre there
    visit_cost: float = 0.5
    visit_radius_m: float = 0.3
    progress_weight: float = 1.0  # waypoint vote: distance gained towards the goal over this cycle's drive ...
    heading_weight: float = 1.0  # ... and how well the rover then faces the goal
    heading_lookahead_m: float = 1.5  # with a path-cost field: heading judged by the cost gained this far along
    use_path_cost: bool = True  # waypoint votes from the path-cost field (False: straight line to the goal)
    traversability_weight: float = 1.0  # arbiter: score = traversability_weight * trav + waypoint_weight * wp
    waypoint_weight: float = 2.0
    # ... plus worst_weight * the lowest goodness the footprint meets within near_distance_m: stereo reads a rock
    # some centimetres low, so a rock just over the limit can look merely "poor"; keep the wheels off poor cells
    worst_weight: float = 1.0
    # ... minus a preference for driving forward: a point turn makes no progress and its footprint (the ground the
    # rover stands on) always votes well; driving backward the rover does not look where it goes.
    backward_penalty: float = 0.1
    point_turn_penalty: float = 0.15
    min_traversability_vote: float = 0.2  # arcs voted below this are never chosen
    # taking back the previous move (the opposite point turn; driving back along the circle just driven, within
    # undo_curvature_per_m) costs this much: it breaks left-right-left dithering, yet a real dead end still wins
    undo_penalty: float = 0.3
    undo_curvature_per_m: float = 0.6

    def __post_init__(self) -> None:
        if self.cell_size_m <= 0 or self.map_size_m < 4 * self.cell_size_m:
            raise ValueError("cell_size_m must be > 0 and map_size_m at least 4 cells")
        if self.patch_radius_m < self.cell_size_m:
            raise ValueError(f"patch_radius_m={self.patch_radius_m}: use at least one cell ({self.cell_size_m} m)")
        for name in ("tilt_deg", "roughness_m", "step_m"):
            if not getattr(self, f"benign_{name}") < getattr(self, f"max_{name}"):
                raise ValueError(f"need benign_{name} < max_{name}")
        if self.apex_reach_rad is not None and not 0.0 <= self.apex_reach_rad < 0.5:
            raise ValueError(f"apex_reach_rad={self.apex_reach_rad}: use 0 <= value < 0.5 rad, or None (off)")
        if self.apex_max_slope < 0:
            raise ValueError(f"apex_max_slope={self.apex_max_slope}: use >= 0")
        if self.n_forward_arcs < 1 or self.n_backward_arcs < 0:
            raise ValueError("need at least one forward arc and a non-negative number of backward arcs")
        if self.look_ahead_m + self.rover_half_width_m >= self.map_size_m / 2:
            raise ValueError("look_ahead_m + rover_half_width_m must stay inside the map window (map_size_m / 2)")

    @property
    def window_cells(self) -> int:
        """Cells per side of the evaluated window (50 for 10 m at 20 cm)."""
        return int(round(self.map_size_m / self.cell_size_m))

    @property
    def patch_cells(self) -> int:
        """Patch radius in whole cells (the margin a window needs around it for the plane fits)."""
        return int(np.ceil(self.patch_radius_m / self.cell_size_m - 1e-9))
