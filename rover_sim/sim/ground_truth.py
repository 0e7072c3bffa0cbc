"""The simulator's ground truth at one instant (:meth:`rover_sim.sim.physics.RoverSim.ground_truth`): for logging and
evaluation only, never fed to estimators."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GroundTruth:
    """True rover state at one instant (for logging and evaluation only; never fed to estimators)."""

    t_s: float
    position_m: np.ndarray  # (3,) world
    quat_wxyz: np.ndarray  # (4,) world <- rover
    wheel_slip: np.ndarray  # (6,) WHEELS order, NaN where not rolling
    wheel_sinkage_m: np.ndarray  # (6,)
    wheel_load_n: np.ndarray  # (6,)
    wheel_in_contact: np.ndarray  # (6,) bool
    tilt_deg: float  # angle between the rover z axis and world up
