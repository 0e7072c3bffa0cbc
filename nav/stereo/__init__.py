"""MER area-based stereo: band-pass, SAD window matching, consistency checks, quadratic sub-pixel, XYZ range image.

Maimone, Johnson, Cheng, Willson, Matthies (2005), section 4.1 (details in Goldberg, Maimone, Matthies 2002):
"The images are rectified and bandpass filtered before the SAD operation, a variety of stereo matching consistency
checks are applied after the SAD operation, subpixel disparities are computed by quadratic interpolation of SAD
scores, and XYZ range images are produced as the final result." MER matched 256x256 images (binned 1024x1024).

:func:`compute_disparity` runs the steps in that order, one small function each:

1. :func:`bandpass` - difference of Gaussians on each rectified image (removes brightness/gain differences between
   the cameras and the low-frequency shading; suppresses pixel noise), then :func:`quantise` to small integers.
2. :func:`row_search_window` - the disparities each row is searched over (MER's stereo also searched a limited
   range). A full-range SAD search at quarter resolution finds the disparities each row's neighbourhood contains;
   the full-resolution search covers only those, plus a margin. Hazcams look at the ground, whose disparity grows
   steadily down the image, so a row needs only a few disparities; rows where nothing matches (the sky) are skipped.
3. :func:`sad_search` - sum of absolute differences over a square window for every searched disparity along the
   epipolar line (row). One pass over the disparities gives the best match of every left pixel, the best match of
   every *right* pixel (for the left-right check), the best score per disparity class and the least of their
   second-best scores (for the uniqueness check), and keeps every SAD score so the scores around the winner can be
   read back for step 4.
4. :func:`subpixel_quadratic` - a parabola through the SAD scores at d-1, d, d+1.
5. Consistency checks: :func:`edge_mask` (the winner and both its neighbours were searched), :func:`texture_mask`
   (local RMS of the band-passed image), :func:`match_quality_mask` (the winning SAD is far below a chance match's),
   :func:`uniqueness_mask`, :func:`left_right_mask`, then :func:`discontinuity_mask` on the disparity image (a window
   straddling a depth edge gives up to half a window of one surface the other's disparity: pixels within half a
   window of a jump are dropped).
6. :func:`speckle_mask` - blob filter: small connected islands of disparity are removed (``cv2.filterSpeckles``).

:func:`range_image` adds the XYZ image (camera and rover frames, :mod:`nav.camera` conventions). Invalid pixels are
NaN everywhere. :func:`stereobm_baseline` is plain OpenCV StereoBM, for benchmarks.

Implementation: the SAD engine is ours rather than ``cv2.StereoBM`` because StereoBM exposes neither its SAD scores
(needed for the quadratic fit: its own sub-pixel step is an equiangular fit quantised to 1/16 px) nor the
right-referenced disparities, and cannot search a different range on each row (using it for the search would also
take a second full StereoBM run, on flipped images, for the left-right check). Two engines implement step 3 with the
same results, bit for bit (``tests/nav/test_stereo_engines.py``):

- :class:`nav.stereo.fused.FusedEngine` (the default where numba is installed, as it is with rover-sim): one
  compiled pass per row. Each searched disparity's column sums over the window's rows are carried from row to row
  (one row in, one out), the window sums formed from them, and each key ``SAD * 256 + index`` updates the running
  best with its neighbours' keys, the per-class bests and least second-best (uniqueness), and the right pixel's best
  while it is in a register. A row's state stays in the cache, so its time does not swing with the other core's
  memory traffic.
- :class:`nav.stereo.sad.Engine` (``NAV_STEREO_ENGINE=opencv``; the fallback without numba, so ``nav`` still runs on
  numpy, scipy and OpenCV alone): the bands of rows that search each disparity are stacked, one ``integral`` and one
  subtraction give every band's sums over the window's rows, then per band one ``addWeighted`` (the sums over the
  window's columns) and a running max and three running minima, all inside OpenCV, with the score and the index in
  one float32 key ``SAD + index / 256``.

Windows are clipped at the top, bottom and right image borders (the same pixels for every disparity, so the scores
stay comparable); on the left the window must lie inside the right image. Everything after the search is a few dozen
OpenCV calls on the searched rows, written into buffers kept between calls (:class:`_Pipeline`; a fresh 256 KB array
costs page faults that take longer than the call filling it). On the 256x256 hazcam pairs of ``rover-sim bench
stereo`` (32 disparities) a call with the compiled engine takes about 0.8 times OpenCV's StereoBM in the same process
on this 2-core machine (0.9 beside a process streaming memory on the other core; the OpenCV engine: 1.1 and 1.4-1.6);
at 1024x1024 about 0.55. Any size up to 4096 px a side runs with exact sums (int32 keys in the compiled engine; in the
OpenCV engine window sums in int32 where float32 would round, and the SAD volume replaced by the scores beside each
running winner when it would exceed the budget), e.g. full-resolution 1024x1024 navcam pairs, 741x500 or 640x480
(Rocky 8) images. From 512x512 px up a call runs on two threads (the caller's and one worker's,
:func:`pipeline_threads`; OpenCV and the compiled kernel release the GIL): the left band-pass beside the right one,
the texture check beside the search, and the search with steps 3-5 split into two row ranges (disjoint rows of every
buffer, exact sums: the same bits as one thread). Smaller images stay on one thread: their many short calls lose
more to GIL hand-offs than the overlap gains.

Modules, in the order of the steps: :mod:`nav.stereo.params` (parameters and result types),
:mod:`nav.stereo.bandpass` (step 1, and the texture check), :mod:`nav.stereo.fused` (the compiled SAD engine, step 3),
:mod:`nav.stereo.sad` (the OpenCV SAD engine, step 3, and sub-pixel interpolation, step 4), :mod:`nav.stereo.checks`
(steps 5-6), :mod:`nav.stereo.pipeline` (the whole pipeline, the row windows of step 2, the step functions that
share its buffers, and the XYZ range images).
"""

from nav.stereo.bandpass import bandpass, quantise, texture_mask
from nav.stereo.checks import (
    discontinuity_mask,
    edge_mask,
    left_right_mask,
    match_quality_mask,
    speckle_mask,
    uniqueness_mask,
)
from nav.stereo.matcher import SadStereo, range_image_with
from nav.stereo.params import RangeImage, RowWindow, SadSearch, StereoParams
from nav.stereo.pipeline import (
    compute_disparity,
    disparity_to_xyz_cam,
    pipeline_threads,
    range_image,
    row_search_window,
    sad_engine,
    sad_search,
    stereobm_baseline,
    xyz_cam_to_rover,
)
from nav.stereo.sad import subpixel_quadratic

__all__ = [
    "SadStereo",
    "range_image_with",
    "RangeImage",
    "RowWindow",
    "SadSearch",
    "StereoParams",
    "bandpass",
    "compute_disparity",
    "discontinuity_mask",
    "disparity_to_xyz_cam",
    "edge_mask",
    "left_right_mask",
    "match_quality_mask",
    "pipeline_threads",
    "quantise",
    "range_image",
    "row_search_window",
    "sad_engine",
    "sad_search",
    "speckle_mask",
    "stereobm_baseline",
    "subpixel_quadratic",
    "texture_mask",
    "uniqueness_mask",
    "xyz_cam_to_rover",
]
