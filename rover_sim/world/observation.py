"""What the onboard stack is allowed to see: the :class:`Observation` type.

The honesty rule (estimators never read ground truth) is enforced here by type: the onboard entry points
(:mod:`rover_sim.runtime.onboard`) accept exactly :class:`Observation` and refuse anything else, subclasses included,
and an Observation holds only what flight software had on Mars:

- stereo pairs as the cameras delivered them, each with the *calibrated* camera models flight software holds
  (computed at the commanded mast pointing, not the physically pointed mast). In the ideal profile the images
  arrive rectified (pinhole cameras) and ``calibration`` is None; with ``[sensors.lens]`` on (flight profile) they
  are **raw** (distorted through the true lenses, unrectified), ``calibration`` holds the calibrated left/right
  CAHVOR or fisheye models (:mod:`nav.lens`) and ``rig`` is the rectified pinhole rig those models define
  (:func:`nav.rectify.rectified_rig`); the onboard stack rectifies before stereo and VO
  (:meth:`rover_sim.runtime.onboard.Onboard.rectified`);
- IMU and wheel/steering encoder samples since the previous observation;
- the commanded mast pointing;
- the operator-given start pose of the drive (from the previous localisation and sun finding);
- the sun's direction in the site frame, from the ephemeris and the clock (MER computed it onboard from time; it
  is knowledge, not a measurement of the simulated state).

No pose, velocity, slip, sinkage or contact from the simulator appears here; those go to the evaluator only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from collections.abc import Mapping

    from nav.camera import StereoRig
    from nav.rectify import StereoCalibration
    from nav.trajectory import Pose
    from nav.types import EncoderSample, ImuSample


@dataclass(frozen=True)
class StereoImages:
    """One stereo pair: greyscale images (uint8, H x W) and the onboard (calibrated) camera models.

    ``calibration`` None: the images are rectified for ``rig``. Otherwise they are raw, and ``rig`` is the rectified
    rig of ``calibration`` (what stereo and VO see after :meth:`~rover_sim.runtime.onboard.Onboard.rectified`)."""

    camera: str  # "navcam", "hazcam_front" or "hazcam_rear"
    t_s: float
    left_u8: np.ndarray
    right_u8: np.ndarray
    rig: StereoRig
    calibration: StereoCalibration | None = None  # the calibrated raw models (flight profile)


@dataclass(frozen=True)
class Observation:
    """Sensor data handed to the onboard stack at one instant (see the module docstring for what is excluded)."""

    t_s: float
    imu: tuple[ImuSample, ...] = ()
    encoders: tuple[EncoderSample, ...] = ()
    images: Mapping[str, StereoImages] = field(default_factory=lambda: MappingProxyType({}))
    mast_pan_deg: float = 0.0  # commanded; left positive
    mast_elevation_deg: float = 0.0  # commanded; up positive
    start_pose: Pose | None = None  # operator-given start of the drive
    sun_direction_world: np.ndarray | None = None  # ephemeris: unit vector sunlight travels along (site frame)

    def pair(self, camera: str) -> StereoImages:
        """The stereo pair of ``camera``; a clear error if this observation has none."""
        try:
            return self.images[camera]
        except KeyError:
            have = ", ".join(self.images) or "none"
            raise KeyError(f"this observation has no {camera} pair (it has: {have})") from None


class NotAnObservation(TypeError):
    """Raised when the onboard stack is handed anything but an :class:`Observation` (the honesty rule)."""


def require_observation(obj: object, where: str) -> Observation:
    """Return ``obj`` if it is exactly an :class:`Observation`; otherwise refuse (subclasses could smuggle truth)."""
    if type(obj) is not Observation:
        raise NotAnObservation(
            f"{where} accepts only rover_sim.world.observation.Observation (sensor data), got "
            f"{type(obj).__module__}.{type(obj).__qualname__}: the onboard stack never sees ground truth"
        )
    return obj  # type: ignore[return-value]
