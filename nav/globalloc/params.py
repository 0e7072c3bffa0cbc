"""Parameters of the built-in global localiser (:class:`nav.globalloc.OrbitalLocalizer`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from nav.stereo import StereoParams


@dataclass(frozen=True)
class GlobalLocParams:
    """Local map, search and refusal thresholds. The refusal thresholds are statistical (a false-alarm rate and
    standard deviations), not fitted to the benchmark's outcomes."""

    # local orthomosaic from the panorama (a ring around the rover)
    binning: int = 2  # panorama pairs are binned by this before stereo (1024 -> 512 px)
    stereo: StereoParams = field(default_factory=lambda: StereoParams(num_disparities=64, window_px=9))
    min_range_m: float = 3.0  # nearer ground is hidden by the rover and its shadow
    max_range_m: float = 24.0  # farther ground is too sparse and too uncertain in range
    highpass_sigma_m: float = 1.0  # shading, exposure and slope brightness removed below this scale
    min_cells: int = 800  # fewer valid local-map cells: refuse ("too little ground seen")
    # search: within the prior's uncertainty
    search_sigmas: float = 3.0  # position and yaw searched over +- this many prior sigmas
    yaw_step_deg: float = 0.5
    # refusal (see nav.globalloc.decide)
    false_alarm: float = 1e-3  # probability that noise alone passes the significance test anywhere in the search
    uniqueness_sigmas: float = 3.0  # the best must beat the best elsewhere by this many standard errors
    exclusion_m: float = 1.0  # "elsewhere": farther than this from the best (the false-fix distance)
    max_sigma_m: float = 0.25  # refuse when the fix's 1-sigma major axis is larger (a 1 m error would be 4 sigma)
    dem_chi2_sigmas: float = 4.0  # DEM residual at the fix: mean chi-square at most 1 + this many of its std
    dem_stereo_sigma_m: float = 0.1  # local elevation's own error per 1 m cell (stereo), beside the DEM's
