"""Sensor sample and rover-geometry types shared by the navigation stack and the simulator.

Wheel order everywhere: ``WHEELS = ("lf", "lm", "lr", "rf", "rm", "rr")`` (left/right, front/middle/rear).
Steered corner wheels: ``STEERED = ("lf", "lr", "rf", "rr")``. Angles in radians, positive by the right-hand rule
about the axis named (wheel spin about the wheel's +y axis in the rover frame, so forward rolling is positive;
steering about +z, so positive steers the wheel's heading to the left).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

WHEELS: tuple[str, ...] = ("lf", "lm", "lr", "rf", "rm", "rr")
STEERED: tuple[str, ...] = ("lf", "lr", "rf", "rr")


@dataclass(frozen=True)
class ImuSample:
    """One IMU sample in the IMU (= rover body) frame: gyro rate and specific force (accelerometer)."""

    t_s: float
    gyro_rad_s: np.ndarray  # (3,)
    accel_m_s2: np.ndarray  # (3,) specific force; at rest on level ground about (0, 0, +g)


@dataclass(frozen=True)
class EncoderSample:
    """Quantised wheel and steering encoder readings."""

    t_s: float
    wheel_angle_rad: np.ndarray  # (6,) in WHEELS order, cumulative
    steer_angle_rad: np.ndarray  # (4,) in STEERED order


@dataclass(frozen=True)
class RoverGeometry:
    """What the onboard software knows about the vehicle (nominal, as flight software would)."""

    wheel_radius_m: float = 0.125
    # wheel contact-point positions (x forward, y left) in the rover frame, WHEELS order
    wheel_xy_m: np.ndarray = field(
        default_factory=lambda: np.array(
            [[0.55, 0.55], [0.0, 0.55], [-0.55, 0.55], [0.55, -0.55], [0.0, -0.55], [-0.55, -0.55]]
        )
    )
    # height of the rover-frame origin above the ground plane through the wheel contacts at the home pose
    body_height_m: float = 0.5
