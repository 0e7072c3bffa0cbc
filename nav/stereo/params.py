"""Parameters and results of the MER stereo pipeline (Maimone et al. 2005, section 4.1): :class:`StereoParams`
(the tuning of every step), :class:`RowWindow` (step 2's output), :class:`SadSearch` (step 3's output) and
:class:`RangeImage` (the paper's "XYZ range images", the final result).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Larger than any SAD score (window <= 21x21 px, quantised values <= 2 * 63): marks "no valid disparity".
NO_MATCH = float(2**20)
# Disparity index stored in the fractional bits of a SAD key: key = SAD + index / TAG (exact in float32).
TAG = 256


@dataclass(frozen=True)
class StereoParams:
    """Tuning of :func:`compute_disparity`; defaults for 256x256 MER navigation images (4x4-binned 1024^2)."""

    num_disparities: int = 64  # search range; navcam (fx ~309 px, 20 cm) sees ground at 1.5 m at ~41 px
    min_disparity: int = 0  # first disparity searched (px, >= 0)
    window_px: int = 9  # SAD window side (odd): 3.5 % of a 256 px image
    # Band-pass (difference of Gaussians): the fine sigma suppresses pixel noise and aliasing of the binned images;
    # the coarse one removes shading and any gain/offset difference between the two cameras.
    bandpass_sigma_fine_px: float = 0.6
    bandpass_sigma_coarse_px: float = 2.5
    # The band-passed image is scaled so that its mean absolute value maps to `quantise_mad_levels` integer levels
    # and clipped to +-`quantise_cap` (6-bit signed, like a flight fixed-point implementation; clipping also stops a
    # single bright edge dominating a window). The scale never exceeds 1/`quantise_min_mad_grey` levels per grey
    # level, so a featureless image is not amplified into noise.
    quantise_cap: int = 31
    quantise_mad_levels: float = 8.0
    quantise_min_mad_grey: float = 0.5
    # Texture: local RMS of the band-passed image (grey levels of the 8-bit input) over the window. 0.5 keeps the
    # dark, low-contrast ground in the rover's shadow (whose matches are as good as the sunlit ones).
    texture_threshold: float = 0.5
    # Uniqueness: the best SAD more than 1 px from the winner must exceed the winner's by this fraction of the
    # winner's valley depth (see uniqueness_mask). Good matches on rocky texture score >= 1.0 (99 %), a perfectly
    # periodic texture ~0.01.
    uniqueness_ratio: float = 0.5
    lr_max_diff_px: int = 1  # left-right check: |dL(u) - dR(u - dL)| <= this (integer disparities)
    # Match quality: the winning SAD must be at most this fraction of window area x local RMS texture (quantised);
    # a chance match scores about 1.1, good matches 0.2-0.4. 0 = off.
    max_sad_ratio: float = 0.8
    # Depth-edge check: a pixel is dropped when a valid pixel within half a window has a disparity more than this
    # much smaller or larger (its window reached across a depth edge). 0 = off.
    discontinuity_px: float = 1.5
    speckle_window_size: int = 40  # blobs of fewer pixels than this are removed (0 = off)
    speckle_range_px: float = 1.0  # neighbours closer than this in disparity belong to the same blob
    # Per-row search window (row_search_window): on, and the margin (px) added on both sides of the disparities
    # found at quarter resolution (sub-pixel there, so about +-1 px here). Off: every row searches the whole range.
    row_window: bool = True
    row_window_margin_px: int = 2

    def __post_init__(self) -> None:
        if self.num_disparities <= 0 or self.num_disparities % 16 or self.num_disparities > TAG:
            raise ValueError(f"num_disparities={self.num_disparities}: use a positive multiple of 16, at most {TAG}")
        if self.min_disparity < 0:
            raise ValueError(f"min_disparity={self.min_disparity}: must be >= 0 (rectified pair, u_right <= u_left)")
        if self.window_px < 3 or self.window_px % 2 == 0 or self.window_px > 21:
            raise ValueError(f"window_px={self.window_px}: use an odd window between 3 and 21 px")
        if not 0 < self.bandpass_sigma_fine_px < self.bandpass_sigma_coarse_px:
            raise ValueError("band-pass sigmas: need 0 < bandpass_sigma_fine_px < bandpass_sigma_coarse_px")
        if self.uniqueness_ratio < 0:
            raise ValueError(f"uniqueness_ratio={self.uniqueness_ratio}: use >= 0 (0 keeps any strictly unique match)")
        if not 1 <= self.quantise_cap <= 63:
            raise ValueError(f"quantise_cap={self.quantise_cap}: use 1..63 (values are stored in uint8)")
        if self.max_sad_ratio < 0:
            raise ValueError(f"max_sad_ratio={self.max_sad_ratio}: use >= 0 (0 = off)")
        if self.discontinuity_px < 0:
            raise ValueError(f"discontinuity_px={self.discontinuity_px}: use >= 0 (0 = off)")
        if self.row_window_margin_px < 1:
            raise ValueError(f"row_window_margin_px={self.row_window_margin_px}: use >= 1 (the winner's neighbours)")

    @property
    def half_window_px(self) -> int:
        return self.window_px // 2

    def for_resolution(self, resolution_px: int, base_px: int = 256) -> StereoParams:
        """These parameters (meant for ``base_px`` images) for images ``resolution_px`` wide: the disparity range
        scales with the image (same range in metres, a multiple of 16, at most 256), the band-pass sigmas with its
        square root (finer images of the same scene carry less texture per pixel). The square-root rule was chosen
        on rendered 1024^2 hazcam pairs of seeds 5-6 (``bench stereo`` scores seeds 0-2)."""
        from dataclasses import replace

        f = resolution_px / base_px
        n_disp = min(TAG, max(16, int(round(self.num_disparities * f / 16)) * 16))
        return replace(
            self,
            num_disparities=n_disp,
            bandpass_sigma_fine_px=self.bandpass_sigma_fine_px * f**0.5,
            bandpass_sigma_coarse_px=self.bandpass_sigma_coarse_px * f**0.5,
        )


@dataclass(frozen=True)
class RangeImage:
    """Output of :func:`range_image`: disparity and XYZ per left-image pixel, NaN where invalid."""

    disparity_px: np.ndarray  # (H, W) float32
    xyz_cam_m: np.ndarray  # (H, W, 3) left camera frame (x right, y down, z forward)
    xyz_rover_m: np.ndarray  # (H, W, 3) rover frame (x forward, y left, z up)
    valid: np.ndarray  # (H, W) bool

    def points_rover_m(self) -> np.ndarray:
        """The valid rover-frame points as an (N, 3) array."""
        return self.xyz_rover_m[self.valid]


@dataclass(frozen=True)
class RowWindow:
    """Disparity indices searched on each row: ``lo[v] <= index <= hi[v]`` (disparity = min_disparity + index).

    A row with ``lo > hi`` is not searched. A row may be searched at a few more disparities (bands of rows a few rows
    apart are merged); only winners strictly inside its window count.
    """

    lo: np.ndarray  # (H,) int32
    hi: np.ndarray  # (H,) int32

    @staticmethod
    def full(h_px: int, num_disparities: int) -> RowWindow:
        return RowWindow(np.zeros(h_px, np.int32), np.full(h_px, num_disparities - 1, np.int32))


@dataclass(frozen=True)
class SadSearch:
    """What one pass of :func:`sad_search` over the disparities leaves behind (all (H, W) in left pixels)."""

    index: np.ndarray  # int32 winning disparity index (disparity = min_disparity + index); -1 where none
    cost: np.ndarray  # float32 winning SAD
    cost_minus: np.ndarray  # float32 SAD at index - 1 (>= NO_MATCH if not searched; see edge_mask)
    cost_plus: np.ndarray  # float32 SAD at index + 1 (likewise)
    second_cost: np.ndarray  # float32 best SAD more than 1 px away from the winner
    right_index: np.ndarray  # int32 winning index of each *right* pixel (column u_right); -1 where none
    window: RowWindow  # the disparity indices searched on each row
