"""Rock-based cross-site localisation: rocks from dense stereo ground points, rock models, matching, adjustment.

Li, Di, Agarwal, Wang, Matthies, Howard, "Automation of ground image based Mars rover localization" (REFERENCE.md
section 5). Rocks are extracted from the dense 3D ground points of a navcam stereo panorama taken at a rover *site*
(a stop), modelled by analytic surfaces, matched between two sites and used as tie points in an incremental
adjustment of the rover positions.

0. Dense points: :func:`panorama_points` turns one large navcam pair into rover-frame points at two scales (the
   near field binned, the far field at full resolution), through :func:`disparity_tiled` (MER SAD stereo,
   :mod:`nav.stereo`, in strips of rows, since one call is limited to about 512 x 512 pixels),
   :func:`refine_disparity` (Lucas-Kanade sub-pixel refinement) and :func:`drop_depth_edges` (no mixed-depth
   points along rock outlines).

:func:`extract_rocks` then reads as the paper's steps in order:

1. :func:`extract_peaks` - rock peaks: local height maxima in a window (50 x 50 cm), with a height range in the
   window above a threshold (10 cm) and enough points in it.
2. :func:`fit_local_plane` - a robust plane through the ground points around the peak; the rock height is the
   peak's distance to it, and the points above it are the rock candidates.
3. :func:`grow_rock_region` - region growing from the peak: radius 0.3 h, grown by the largest nearest-neighbour
   spacing per step, stopped at 1.7 h or when nothing is added.
4. :func:`fit_rock_model` / :func:`fit_best_model` - least-squares fits of a hemispheroid, a semi-ellipsoid, a cone
   and a tetrahedron with iterative removal of far points; the model with the lowest
   information criterion (RMS penalised by its number of parameters) is kept.

Then, between sites:

5. :func:`match_rocks` - candidate pairs by model parameters (height, size, volume, surface area), then the
   geometric pattern of the rock positions (a RANSAC over pairs of candidates for a 4-DOF transform: yaw and
   translation, since roll and pitch come from the accelerometers), then a weighted least-squares transform from the
   consistent matches and a significance test against chance agreement.
6. :class:`SiteChain` - incremental adjustment of a chain of sites (the paper: matched rocks are tie points of an
   incremental bundle adjustment), as a weighted least-squares pose graph: unknown site poses (x, y, z, yaw) and
   systematic tie-point error terms, observed as odometry legs between consecutive sites (VO's own covariance, the
   gyro's heading drift) and as site-to-site transforms from the matched rocks (covariance from the fit, scaled by
   the match residuals; gross tie points screened out first by :func:`robust_tie_points`), solved every time a
   site is added.

Ground processing between 5 and 6 (:mod:`nav.rocks.range_bias`): the panorama pair's stereo range bias (a toe-in
calibration error adds a constant to inverse range) is fitted from the rocks matched between sites and the rocks moved
back along their lines of sight before the final adjustment (self-calibrating bundle adjustment cut to one parameter).

Frames: each site's points and rocks are in that site's *estimated* world frame (x east, y north, z up), i.e. rover
frame points mapped through the onboard pose estimate at the site; the estimates of two sites differ from the truth
and from each other by the odometry drift, which is what matching and adjustment recover. A :class:`Pose4` maps
points of one frame into another. Pure numpy/scipy/OpenCV: nothing here reads ground truth or any simulator state.

Modules, in the order of the steps: :mod:`nav.rocks.params` (parameters and data types), :mod:`nav.rocks.dense`
(step 0, dense points), :mod:`nav.rocks.extract` (steps 1-3 and the extraction pipeline), :mod:`nav.rocks.models`
(step 4), :mod:`nav.rocks.match` (step 5), :mod:`nav.rocks.range_bias` (between 5 and 6), :mod:`nav.rocks.chain`
(step 6).
"""

from nav.rocks.chain import ChainParams, ChainSite, SiteChain, robust_tie_points
from nav.rocks.dense import (
    PanoramaStereoParams,
    disparity_tiled,
    drop_depth_edges,
    panorama_points,
    refine_disparity,
    voxel_downsample,
)
from nav.rocks.extract import (
    RockObservation,
    extract_peaks,
    extract_rocks,
    fit_local_plane,
    fit_plane_robust,
    grow_rock_region,
    observation_quality,
    top_point,
)
from nav.rocks.match import (
    MatchParams,
    Pose4,
    SiteMatch,
    SiteRocks,
    descriptor_difference,
    fit_pose4,
    match_rocks,
    tie_point_covariances,
)
from nav.rocks.models import PointNoise, fit_best_model, fit_rock_model, model_distance, selection_criterion
from nav.rocks.params import ROCK_SHAPES, ExtractedRock, LocalPlane, RockModel, RockParams, RockPeak, RockShape

__all__ = [
    "ChainParams",
    "ChainSite",
    "ExtractedRock",
    "LocalPlane",
    "MatchParams",
    "PanoramaStereoParams",
    "PointNoise",
    "Pose4",
    "ROCK_SHAPES",
    "RockModel",
    "RockObservation",
    "RockParams",
    "RockPeak",
    "RockShape",
    "SiteChain",
    "SiteMatch",
    "SiteRocks",
    "descriptor_difference",
    "disparity_tiled",
    "drop_depth_edges",
    "extract_peaks",
    "extract_rocks",
    "fit_best_model",
    "fit_local_plane",
    "fit_plane_robust",
    "fit_pose4",
    "fit_rock_model",
    "grow_rock_region",
    "match_rocks",
    "model_distance",
    "observation_quality",
    "panorama_points",
    "refine_disparity",
    "robust_tie_points",
    "selection_criterion",
    "tie_point_covariances",
    "top_point",
    "voxel_downsample",
]
