"""Examples of user-supplied parts for the onboard stack, shipped with rover-sim so that they can be named from any
installation.

:mod:`rover_sim.examples.opencv_vo` — ``OpenCvStereoVO``, a compact stereo visual odometer built from stock OpenCV
parts (Shi-Tomasi corners, row NCC stereo, KLT tracking seeded by the dead-reckoning prediction,
``solvePnPRansac``). It is written only against :class:`nav.protocols.VisualOdometer` and shows how to bring your
own VO; it has none of the MER flight checks of the built-in :class:`nav.vo.VisualOdometry`. Plug it in by its
import path::

    rover-sim bench vo --vo rover_sim.examples.opencv_vo:OpenCvStereoVO    # its rows next to the built-in's
    rover-sim run wopmay --vo rover_sim.examples.opencv_vo:OpenCvStereoVO

or in a scenario file: ``[nav.vo] impl = "rover_sim.examples.opencv_vo:OpenCvStereoVO"``. A VO of your own is
named the same way (``mypkg.vo:MyVO``: any importable module) or by an entry point in ``rover_sim.plugins``.
"""

EXAMPLE_VO = "rover_sim.examples.opencv_vo:OpenCvStereoVO"  # the import path that names the example VO
