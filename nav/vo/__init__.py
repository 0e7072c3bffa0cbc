"""Stereo visual odometry as flown on the Mars Exploration Rovers (Cheng, Maimone, Matthies 2005).

:meth:`VisualOdometry.step` reads as the paper's list:

1. feature detection (Harris, grid, minimum spacing)  -> :func:`nav.vo.features.detect_features`
2. stereo matching (pseudo-normalised correlation)    -> :func:`nav.vo.features.stereo_match_features`
3. triangulation with a gap test                      -> :func:`nav.vo.motion.triangulate_rays`
4. covariance per feature                             -> :func:`nav.vo.motion.feature_covariance`
5. tracking with the dead-reckoning prediction        -> :func:`nav.vo.tracking.track_features`
6. RANSAC over weighted closed-form least squares     -> :func:`nav.vo.motion.ransac_motion`
7. maximum-likelihood refinement                      -> :func:`nav.vo.motion.ml_refine`
8. sanity constraints                                 -> :func:`nav.vo.motion.sanity_check`
9. failure handling: no update, the dead-reckoned motion stands; over-large steps re-initialise.

Frames: features live in the rover frame of their image (``rig.left.T_rover_cam`` places the cameras). The
result ``motion_rover`` is the pose of the current rover frame in the previous one, the same convention as the
``predicted_motion_rover`` from dead reckoning.

Robustness guards added to the paper's checks (all in :class:`~nav.vo.params.VoParams`), motivated by its
section 4.3 false positives: inliers must spread over the image (Sols 137/141, features clustered on one flat
patch); a second, different consensus among the rejected features means two rigid motions are in view, such as
the terrain and the rover's own shadow (Sol 235), and the step is refused; a solution whose covariance is too
large is refused. Declining an update costs only the dead-reckoning error of one step; a false update can be
far worse.

Modules: :mod:`nav.vo.params` (every threshold), :mod:`nav.vo.features` (steps 1-2 and the correlation search),
:mod:`nav.vo.motion` (steps 3-4 and 6-8), :mod:`nav.vo.tracking` (feature frames, step 5),
:mod:`nav.vo.pipeline` (:class:`VisualOdometry`, step 9).
"""

from nav.vo.features import (
    WindowStats,
    correlate_window,
    detect_features,
    fit_biquadratic_peak,
    pseudo_normalized_correlation,
    stereo_match_features,
    window_at,
    window_stats,
)
from nav.vo.motion import (
    RansacResult,
    downslope_direction,
    feature_covariance,
    gap_test,
    ml_refine,
    motion_from_RT,
    motion_magnitude,
    ransac_motion,
    reprojection_error_px,
    sanity_check,
    triangulate_rays,
    triangulate_stereo,
)
from nav.vo.params import SanityConstraints, VoParams
from nav.vo.pipeline import VisualOdometry, VoResult, VoStatus
from nav.vo.tracking import FeatureFrame, FeatureTracks, build_feature_frame, track_features, warped_templates

__all__ = [
    "FeatureFrame",
    "FeatureTracks",
    "RansacResult",
    "SanityConstraints",
    "VisualOdometry",
    "VoParams",
    "VoResult",
    "VoStatus",
    "WindowStats",
    "build_feature_frame",
    "correlate_window",
    "detect_features",
    "downslope_direction",
    "feature_covariance",
    "fit_biquadratic_peak",
    "gap_test",
    "ml_refine",
    "motion_from_RT",
    "motion_magnitude",
    "pseudo_normalized_correlation",
    "ransac_motion",
    "reprojection_error_px",
    "sanity_check",
    "stereo_match_features",
    "track_features",
    "triangulate_rays",
    "triangulate_stereo",
    "warped_templates",
    "window_at",
    "window_stats",
]
