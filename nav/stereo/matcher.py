"""The built-in :class:`nav.protocols.StereoMatcher`: MER SAD stereo (seed 001 section 3) behind the protocol."""

from __future__ import annotations

import numpy as np

from nav.camera import StereoRig
from nav.stereo.params import RangeImage, StereoParams
from nav.stereo.pipeline import compute_disparity, disparity_to_xyz_cam, xyz_cam_to_rover


class SadStereo:
    """Band-pass, SAD correlation, sub-pixel fit and the paper's consistency checks (``compute_disparity``)."""

    def __init__(self, params: StereoParams | None = None) -> None:
        self.params = params or StereoParams()

    def disparity(self, left_u8: np.ndarray, right_u8: np.ndarray, rig: StereoRig | None = None) -> np.ndarray:
        return compute_disparity(left_u8, right_u8, self.params)


def range_image_with(matcher: object, left_u8: np.ndarray, right_u8: np.ndarray, rig: StereoRig) -> RangeImage:
    """Disparity from any :class:`nav.protocols.StereoMatcher`, then camera- and rover-frame XYZ through ``rig``."""
    disparity = matcher.disparity(left_u8, right_u8, rig)  # type: ignore[attr-defined]
    xyz_cam = disparity_to_xyz_cam(disparity, rig)
    valid = np.isfinite(xyz_cam[..., 2])
    return RangeImage(disparity, xyz_cam, xyz_cam_to_rover(xyz_cam, rig.left), valid)
