"""Tuning parameters of the MER visual odometry (Cheng, Maimone, Matthies 2005), one place, with units.

Defaults are for 256x256 navigation images (MER navcams binned 4x4: 45 deg FOV, 20 cm baseline). Numbers the
paper gives are marked "paper"; the rest are chosen here and say why.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class VoParams:
    """Every threshold of :class:`nav.vo.VisualOdometry`."""

    # --- step 1: feature detection (Harris corners on the left image, grid, minimum spacing) ---
    max_features: int = 150  # paper: "a fixed number" (no value given); 100-200 suits 256^2 images
    # Minimum distance between features. Paper (Sols 137/141): too small a spacing let features cluster on one
    # flat patch and gave false solutions; 15 px keeps 150 features spread over a 256^2 image.
    min_spacing_px: float = 15.0
    harris_block_px: int = 5  # structure-tensor averaging window
    harris_k: float = 0.04
    # Candidates weaker than this fraction of the strongest response are dropped. Kept tiny: a high-contrast
    # shadow edge must not suppress the weak terrain texture (Sol 235); flat or noise-only windows fail the
    # stereo checks.
    harris_rel_threshold: float = 1e-7
    border_px: int = 8  # no features closer than this to the image edge (window half-size + sub-pixel margin)

    # --- step 2: stereo matching (pseudo-normalised correlation along the epipolar line) ---
    window_px: int = 11  # correlation window (odd); the paper gives no size, 11x11 suits 256^2 images
    row_slack_px: int = 2  # paper: "a few pixels of offset buffer above and below" the epipolar line
    min_disparity_px: int = 1
    max_disparity_px: int = 80  # navcam at 1.5 m: nearest ground in view ~1.5 m -> ~40 px; margin for rigs lower down
    min_correlation: float = 0.8  # pseudo-normalised score of an accepted stereo match
    # A window whose grey-level standard deviation is below this is textureless: its correlation peak is
    # noise.
    min_window_std_grey: float = 2.0
    # Sensor noise used to turn the correlation-peak curvature into a position covariance (see vo_features).
    image_noise_grey: float = 1.0
    min_match_sigma_px: float = 0.05  # floor on the per-axis match standard deviation (interpolation bias)

    # --- step 3: triangulation with a gap test ---
    max_ray_gap_px: float = 1.0  # ray gap |P1 - P2| expressed as an image-plane distance at the feature's range
    max_range_m: float = 30.0

    # --- step 5: tracking (predict with dead reckoning, correlate around the prediction, re-match stereo) ---
    # Resample each previous window through the ground-plane homography of the predicted motion before
    # correlating (see nav.vo.warped_templates; not in the paper, which correlated raw windows). False = the
    # paper's tracking.
    track_warp_templates: bool = True
    track_search_radius_px: int = 16  # full-resolution search around the predicted position
    # A second, coarse-to-fine search: this radius on the half-resolution images (+-48 px at full resolution:
    # about a 0.35 m prediction error at 2-3 m range), then +-track_refine_radius_px at full resolution; the
    # better-correlated of the two matches is kept. 0 disables the coarse search.
    track_coarse_search_radius_px: int = 24
    track_refine_radius_px: int = 2
    min_track_correlation: float = 0.7  # lower than stereo: the view changes between frames
    # Re-matching tracked features in stereo searches only the disparities of depths within max_track_shift_m of
    # the predicted 3D position (the paper's reduced search range), widened by this slack.
    track_disparity_slack_px: int = 3
    # Drop a tracked feature whose new 3D position differs from the predicted one by more than this. Slip can
    # make the prediction wrong by a whole step (<= 0.75 m), so this only removes gross stereo/tracking
    # mismatches.
    max_track_shift_m: float = 0.75

    # --- step 6: RANSAC with weighted closed-form least squares ---
    ransac_subset_size: int = 6  # paper: "e.g. 6"
    ransac_iterations: int = 200  # paper: "a fixed number of iterations"
    inlier_threshold_px: float = 0.75  # paper: "e.g. 0.5"; 0.75 px allows for the correlation's view-change bias
    ransac_seed: int = 0

    # --- step 7: maximum-likelihood refinement ---
    ml_max_iterations: int = 30
    ml_tol_rad: float = 1e-9  # convergence: rotation increment below this ...
    ml_tol_m: float = 1e-8  # ... and translation increment below this
    # After convergence, features with Mahalanobis residual e^T W e above this chi^2(3) value (99.9 %) are
    # dropped and the estimate is recomputed once (None disables this addition to the paper).
    ml_outlier_chi2: float | None = 16.27

    # --- step 9: failure handling ---
    min_features: int = 20  # fewer 3D features in a frame, or tracked into the next one -> "too_few_features"
    min_inliers: int = 15  # fewer RANSAC/ML inliers -> "no_convergence"
    # Overlap limits (paper section 4: steps <= 75 cm, turns <= 18 deg for >= 60 % overlap); larger predicted
    # motion forces a re-initialisation.
    reinit_max_translation_m: float = 0.75
    reinit_max_rotation_deg: float = 18.0
    # A camera repointed between two pairs by at most this (mast pan/tilt) is tracked across, as the features are
    # kept in the rover frame; 15 deg of a 45 deg navcam keeps >= 60 % overlap. Larger -> re-initialise.
    max_repoint_deg: float = 15.0

    # --- guards against false positives (paper section 4.3: Sols 137/141 clustering, Sol 235 shadow) ---
    spread_grid_cells: int = 4  # inliers are binned into a spread_grid_cells x spread_grid_cells grid ...
    min_inlier_cells: int = 5  # ... and must occupy at least this many cells
    min_inlier_hull_fraction: float = 0.12  # convex hull of inlier pixels / image area
    min_inlier_fraction: float = 0.25  # inliers / tracked features
    # A second RANSAC on the features the best motion rejects: a consensus at least this fraction of the best
    # one, moving differently, means two rigid motions are in view (terrain and a rover-fixed shadow) ->
    # refuse.
    ambiguity_ratio: float = 0.4
    ambiguity_min_translation_m: float = 0.02  # motions closer than this (and the angle below) are the same motion
    ambiguity_min_rotation_deg: float = 0.5
    # If of two consensus sets exactly one is fixed to the rover (its features barely move: less than a quarter
    # of what the other motion would move them; the rover's own shadow or hardware) use the other. Off by
    # default: a truly stuck rover (100 % slip) plus a spurious second consensus would then give a false update;
    # refusing is the paper-safe choice.
    resolve_rover_fixed_consensus: bool = False
    max_translation_sigma_m: float = 0.02  # largest 1-sigma axis of the solution's position covariance
    max_rotation_sigma_deg: float = 1.0

    def __post_init__(self) -> None:
        if self.window_px < 3 or self.window_px % 2 == 0:
            raise ValueError(f"window_px={self.window_px}: use an odd window of at least 3 px (e.g. 11)")
        if self.ransac_subset_size < 3:
            raise ValueError(f"ransac_subset_size={self.ransac_subset_size}: a rigid motion needs at least 3 features")
        if not 0 < self.min_disparity_px < self.max_disparity_px:
            raise ValueError("need 0 < min_disparity_px < max_disparity_px (rectified pair, u_right < u_left)")
        if self.min_spacing_px < 2:
            raise ValueError(f"min_spacing_px={self.min_spacing_px}: use at least 2 px (paper: too small clusters)")

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class SanityConstraints:
    """Limits on the VO *update* (paper section 2 step 8, Feb 2005 flight software; REFERENCE 3.4 step 8).

    The update is the VO motion minus the motion predicted by dead reckoning: its translation (expressed in
    the site frame when the previous attitude is given, else in the previous rover frame) and its
    roll/pitch/yaw change. ``None`` disables a limit. A violation counts as a failure to converge.

    On by default with flight-like limits. The paper gives the kinds of limit, not the values; these
    follow from its numbers: a VO step is at most 75 cm (60 % overlap) and slip reached 125 % (Spirit, Sol 206),
    so a true translation update stays under ~1 m; the IMU kept attitude well ("VO was used mostly to update
    position"), so roll/pitch updates beyond a few degrees are VO errors, and yaw (gyro drift plus skid-steer
    slip in a turn) gets more room. The downslope-angle limit stays off: across a slope the slip is a mix of
    downslope and backward, so no single angle separates good from bad updates. Consecutive failures past
    ``max_failures`` halt the drive (the runner's ``halted = "vo_failures"``), as flight software did.
    """

    max_update_m: float | None = 1.0  # |update translation|: 75 cm step x 125 % slip, rounded up
    max_update_x_m: float | None = 1.0  # |site-frame X component| (rover frame if no attitude given)
    max_update_y_m: float | None = 1.0  # |site-frame Y component|
    max_roll_update_deg: float | None = 5.0
    max_pitch_update_deg: float | None = 5.0
    max_yaw_update_deg: float | None = 10.0
    # angle between the translation update and the pure downslope direction (slip goes downhill); ignored for
    # updates shorter than min_update_for_direction_m or on level ground
    max_downslope_angle_deg: float | None = None
    min_update_for_direction_m: float = 0.02
    max_failures: int | None = 12  # consecutive failures tolerated before VoResult.failure_limit_reached
