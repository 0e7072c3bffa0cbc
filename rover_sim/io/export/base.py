"""What the dataset writers share: the :class:`Frame` and :class:`ExportMeta` they are handed, the
:class:`DatasetWriter` interface, the :class:`Stream` guard that keeps every stream's timestamps strictly increasing,
and small frame/time helpers.

Frames: world x east / y north / z up; rover (= body = IMU) x forward / y left / z up; cameras OpenCV (x right,
y down, z forward). ``T_a_b`` maps points of frame ``b`` into frame ``a``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

from nav.camera import StereoRig
from nav.trajectory import Pose
from nav.types import STEERED, WHEELS, EncoderSample, ImuSample

T = TypeVar("T")

WHEEL_JOINTS: tuple[str, ...] = tuple(f"wheel_{w}" for w in WHEELS)  # spin angle, rad, cumulative
STEER_JOINTS: tuple[str, ...] = tuple(f"steer_{w}" for w in STEERED)  # steering angle, rad
MAST_JOINTS: tuple[str, ...] = ("mast_pan", "mast_elevation")  # commanded, rad (pan left +, elevation up +)


def t_ns(t_s: float) -> int:
    """Simulation seconds to integer nanoseconds (EuRoC file names, ROS stamps)."""
    return int(round(t_s * 1e9))


@dataclass(frozen=True)
class Frame:
    """One exported stereo pair.

    ``rig`` is the camera model flight software held (intrinsics, baseline: the calibration to publish; the
    images are rectified for it). ``T_rover_cam`` / ``T_rover_right_cam`` are the *true* poses on the rover, at
    capture, of the cameras the exported images are: on the flight profile the rectified cameras
    (:mod:`rover_sim.io.export.camera_truth`), which differ from the physical ones by the mounting, rectifying and
    calibration rotations; on the ideal profile the physical cameras (they differ from ``rig`` only by the
    mast's servo error). ``T_rover_cam_physical`` is the physical left camera (the MJCF camera at the true mast
    pose); ``truth`` the true rover pose at capture.
    """

    t_s: float
    camera: str
    left_u8: np.ndarray
    right_u8: np.ndarray
    rig: StereoRig
    T_rover_cam: np.ndarray
    T_rover_right_cam: np.ndarray
    T_rover_cam_physical: np.ndarray
    truth: Pose

    @property
    def T_world_cam(self) -> np.ndarray:
        """True pose of the left image's camera in the world."""
        return self.truth.as_matrix() @ self.T_rover_cam


@dataclass(frozen=True)
class ExportMeta:
    """What the writers know about the run before it starts."""

    scenario: str
    seed: int
    camera: str
    mode: str  # "vo-steps" or "rate 2 Hz"
    imu_rate_hz: float = 100.0
    gyro_noise_density: float = 0.0  # rad/s/sqrt(Hz)
    accel_noise_density: float = 0.0  # m/s^2/sqrt(Hz)
    gyro_bias_sigma: float = 0.0  # rad/s (Gauss-Markov bias instability)
    gyro_bias_corr_time_s: float = 0.0
    encoder_rate_hz: float = 8.0
    has_vo: bool = True


class DatasetWriter:
    """Receives the streams of one run in time order per stream and writes them as they arrive.

    Every method may be left as is (no-op); :meth:`close` finishes the files. Timestamps handed to each method are
    strictly increasing (the :class:`~rover_sim.io.export.DatasetSink` guarantees it).
    """

    name = "dataset"

    def start(self, meta: ExportMeta) -> None:
        """Called once before the first sample."""

    def frame(self, frame: Frame) -> None:
        """One stereo pair of the exported camera."""

    def imu(self, sample: ImuSample) -> None:
        """One IMU sample (rover frame)."""

    def encoders(self, sample: EncoderSample, mast_pan_rad: float, mast_elevation_rad: float) -> None:
        """One wheel/steering encoder reading, with the commanded mast angles at that time."""

    def truth(self, pose: Pose) -> None:
        """The true rover pose (8 Hz ticks)."""

    def estimate(self, source: str, pose: Pose) -> None:
        """One of the rover's own estimates, stamped with its own time: ``source`` "dead_reckoning" (pure wheel/IMU)
        or "vo" (the VO-corrected onboard pose; runs with VO only)."""

    def close(self) -> None:
        """Finish and close every file."""


class Stream(Generic[T]):
    """Forwards ``(t, item)`` pairs with strictly increasing ``t``.

    ``keep="first"`` drops an item whose time is not after the last one forwarded (images: the pair already
    written stands); ``keep="last"`` holds one item back so that of equal stamps the last wins (poses: the pose
    recorded again after a VO correction at the same instant), flushed by :meth:`flush`.
    """

    def __init__(self, emit: Callable[[T], None], keep: str = "first") -> None:
        if keep not in ("first", "last"):
            raise ValueError(f"keep must be 'first' or 'last', got {keep!r}")
        self.emit, self.keep = emit, keep
        self.count = 0
        self.dropped = 0
        self.first_t: float | None = None
        self.last_t: float | None = None  # of the last item forwarded (or held)
        self.pending: T | None = None

    def push(self, t_s: float, item: T) -> None:
        last = self.last_t
        if last is not None and (t_s < last or (t_s == last and self.keep == "first")):
            self.dropped += 1
            return
        if self.keep == "first":
            self.emit(item)
        else:
            if self.pending is not None and t_s == last:
                self.dropped += 1  # replaced by the newer item of the same instant
            elif self.pending is not None:
                self.emit(self.pending)
            self.pending = item
        if last is None:
            self.first_t = t_s
        if last is None or t_s > last:
            self.count += 1
        self.last_t = t_s

    def flush(self) -> None:
        if self.pending is not None:
            self.emit(self.pending)
            self.pending = None
