"""``[sensors.lens]``: lens models, camera mounting, calibration and mast-encoder errors.

``profile = "ideal"``: every camera is the MJCF pinhole, images arrive rectified, the onboard rig is exact, the mast
points where commanded (today's behaviour, byte for byte). ``profile = "flight"``: the cameras form raw, distorted
images through the lenses below, the onboard side rectifies them with a *calibration* that differs from the true
cameras by the seeded errors below, and the mast stops within the encoder resolution and backlash of the command.

Defaults of the flight profile and where they come from (1-sigma unless stated; all draws seeded from the scenario
seed, once per run, except the mast error, drawn per repointing):

========================== ============== ==================================================================
field                      flight         source / justification
========================== ============== ==================================================================
navcam_r                   0, -0.010,     CAHVOR R terms of the 45 deg navcams. Maki et al. 2003 (JGR 108 E12,
                           0.003          "MER engineering cameras") describe low-distortion f/12 14.67 mm
                                          optics without publishing R; these give 2.2 px of barrel distortion in
                                          the 1024^2 corners (0.6 px at 256^2), the size of published CAHVOR
                                          fits of such lenses. Assumed, not measured.
hazcam_k                   0.01, -0.002,  Kannala-Brandt terms of the 124 deg hazcams. Maki 2003: f-theta
                           0, 0           fisheye, 2.1 mrad/px at the centre, 124 deg over 1024 px, i.e. within
                                          ~2 % of ``r = f theta``; these k bend the edge by 1.5 % (8 px at 1024).
hazcam_max_off_axis_deg    71             raw hazcam pixels farther off axis are vignetted to 0: a pinhole
                                          render cannot show the lens' 180 deg diagonal. 71 deg keeps the
                                          rectified 124 deg pinhole view (corners at 69.4 deg) fully covered.
render_oversample          1.0            ideal pinhole render's centre magnification / the raw model's
                                          (1: the raw centre pixel is not upsampled). Above 1 each raw pixel
                                          integrates its area of the finer render (``TrueLens``); the rock
                                          survey's panoramas use 2 (``SurveyConfig.render_oversample``).
mount_rotation_deg         0.2            true mounting error of each camera, per axis (build tolerance of a
                                          machined bracket); known to the calibration, so rectification
                                          removes it (row misalignment of 1-3 px at 256^2 without it).
                                          The rectified view is zoomed 1-4 % so that it holds no pixel
                                          outside the raw images (``nav.rectify.valid_zoom``).
camera_rotation_deg        0.05           calibration error of each camera's pointing, per axis, common to both
                                          cameras of a pair (MER navcam/hazcam pointing knowledge ~1 mrad,
                                          Maki 2003 calibration section; 0.05 deg = 0.9 mrad).
stereo_rotation_deg        0.02           calibration error of the right camera relative to the left, per axis:
                                          a stereo calibration leaves 0.1-0.3 px epipolar residuals at 1024^2
                                          (0.82 mrad/px), i.e. 0.1-0.25 mrad of relative pitch; 0.02 deg =
                                          0.35 mrad is above that, kept as the in-flight value (the ground
                                          calibration shifted by launch, landing and temperature; assumed:
                                          no published figure found for the MER pairs). It moves rectified
                                          rows by 0.11 px (1 sigma) at 256^2, 0.43 px at 1024^2, and
                                          dominates the rectified row error: with the ground calibration
                                          alone the median row error of a draw (true vs calibrated models,
                                          256^2 navcam) exceeds the 0.3 px bar in 1.4 % of draws
                                          (1500 draws). The onboard epipolar check (``[nav]
                                          epipolar_check``, ``nav.epipolar``) fits the pitch and roll parts
                                          from the first pairs' rows (where this sigma moves rows by 0.05 px
                                          or more: not the 256^2 hazcams); the toe-in part stays and biases range
                                          (3.4 % at 25 m for 0.27 mrad with the navcams' 20 cm baseline).
baseline_mm                0.3            calibration error of the right camera's position relative to the
                                          left, per axis (assumed; 0.15 % of 20 cm).
focal_length_pct           0.05           relative focal-length error per camera (0.6 px at 1024^2 navcam).
principal_point_px         0.5            principal-point error per axis, full-resolution (1024^2) pixels,
                                          common to both cameras of a pair (the relative part is a rotation).
distortion_residual_pct    5              relative error of each distortion coefficient.
mast_resolution_deg        0.05           pan/tilt encoder quantum: MER PMA actuators with resolvers/encoders
                                          behind 1000:1-class gearheads; pointing knowledge ~1 mrad (0.057 deg).
mast_backlash_deg          0.1            pan/tilt gear backlash: the mast stops short of the command by up to
                                          this, in the direction it moved (uniform in [0, backlash]).
========================== ============== ==================================================================

Errors only act where they can: calibration errors need ``enabled`` (raw images and onboard rectification); the
mast error acts in both cases.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, model_validator

FLIGHT_DEFAULTS: dict[str, Any] = {
    "enabled": True,
    "navcam_r": (0.0, -0.010, 0.003),
    "hazcam_k": (0.01, -0.002, 0.0, 0.0),
    "mount_rotation_deg": 0.2,
    "camera_rotation_deg": 0.05,
    "stereo_rotation_deg": 0.02,
    "baseline_mm": 0.3,
    "focal_length_pct": 0.05,
    "principal_point_px": 0.5,
    "distortion_residual_pct": 5.0,
    "mast_resolution_deg": 0.05,
    "mast_backlash_deg": 0.1,
}
CALIBRATION_FIELDS = ("mount_rotation_deg", "camera_rotation_deg", "stereo_rotation_deg", "baseline_mm",
                      "focal_length_pct", "principal_point_px", "distortion_residual_pct")  # fmt: skip


class LensErrorSpec(BaseModel):
    """``[sensors.lens]`` (see the module docstring for every default and its source)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    enabled: bool = Field(False, description="raw distorted images through the lens models + onboard rectification")
    navcam_r: tuple[float, float, float] = (0.0, 0.0, 0.0)
    hazcam_k: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    hazcam_max_off_axis_deg: float = Field(71.0, ge=65.0, le=80.0)
    render_oversample: float = Field(1.0, ge=0.5, le=2.0)
    mount_rotation_deg: float = Field(0.0, ge=0.0, le=2.0)
    camera_rotation_deg: float = Field(0.0, ge=0.0, le=2.0)
    stereo_rotation_deg: float = Field(0.0, ge=0.0, le=1.0)
    baseline_mm: float = Field(0.0, ge=0.0, le=10.0)
    focal_length_pct: float = Field(0.0, ge=0.0, le=2.0)
    principal_point_px: float = Field(0.0, ge=0.0, le=20.0)
    distortion_residual_pct: float = Field(0.0, ge=0.0, le=50.0)
    mast_resolution_deg: float = Field(0.0, ge=0.0, le=1.0)
    mast_backlash_deg: float = Field(0.0, ge=0.0, le=1.0)

    @classmethod
    def profile_defaults(cls, profile: str) -> dict[str, Any]:
        return dict(FLIGHT_DEFAULTS) if profile == "flight" else {}

    @model_validator(mode="after")
    def _calibration_needs_lens(self) -> LensErrorSpec:
        if not self.enabled:
            bad = [f for f in CALIBRATION_FIELDS if getattr(self, f) != 0.0]
            if bad or any(self.navcam_r) or any(self.hazcam_k):
                raise ValueError(
                    f"sensors.lens.{(bad or ['navcam_r/hazcam_k'])[0]} needs sensors.lens.enabled = true "
                    "(calibration and distortion act through raw images and onboard rectification)"
                )
        return self

    @property
    def has_mast_error(self) -> bool:
        return self.mast_resolution_deg > 0.0 or self.mast_backlash_deg > 0.0
