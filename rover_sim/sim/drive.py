"""MER drive primitives: straight drive, Ackermann arc, turn in place (how the rovers were commanded).

Each primitive steers the four corner wheels first (the rover stands still while they turn), then rolls the six
wheels along a trapezoidal speed profile and **ends when the wheels have turned the commanded amount** (wheel
odometry), exactly as MER's blind drives did: on sand the rover then stands short of the goal by the slip.

Geometry: the instantaneous centre of rotation (ICR) of an arc of radius ``R`` lies at ``(0, R)`` in the rover
frame (on the axle line of the unsteered middle wheels; ``R > 0`` turns left). A wheel at ``p`` moves along
``Omega z x (p - ICR)``, so its steering angle is ``atan2(p_x, R - p_y)`` and its speed is proportional to
``|p - ICR|``. A point turn is the arc with the ICR at the rover origin.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nav.types import STEERED, WHEELS, RoverGeometry
from rover_sim.sim.physics import RoverSim

MAX_WHEEL_SPEED_M_S = 0.05  # MER peak drive speed (REFERENCE.md section 1)
NOMINAL_SPEED_M_S = 0.0375  # typical MER drive speed
ACCEL_M_S2 = 0.05  # speed ramp: full speed in 1 s
TICK_S = 0.125  # 8 Hz onboard pose-update cycle
STEER_TOLERANCE_RAD = math.radians(0.5)
STEER_TIMEOUT_S = 10.0
_STEER_INDEX = [WHEELS.index(w) for w in STEERED]


@dataclass(frozen=True)
class Straight:
    """Drive straight ``distance_m`` (negative = backwards)."""

    distance_m: float


@dataclass(frozen=True)
class Arc:
    """Drive ``distance_m`` (path length at the rover origin) on an arc of ``radius_m`` (> 0 turns left)."""

    radius_m: float
    distance_m: float


@dataclass(frozen=True)
class TurnInPlace:
    """Turn in place by ``angle_rad`` (> 0 = counter-clockwise seen from above)."""

    angle_rad: float


Primitive = Straight | Arc | TurnInPlace


@dataclass(frozen=True)
class WheelPlan:
    """Steering angles (STEERED order) and wheel travel per unit of primitive progress (WHEELS order, metres)."""

    steer_rad: np.ndarray
    wheel_travel_m: np.ndarray  # signed rim travel of each wheel for the whole primitive
    body_travel: float  # metres (straight/arc) or radians (turn) of the whole primitive


def _plan_about_icr(icr_xy: np.ndarray, omega_sign: float, scale: float, geom: RoverGeometry) -> tuple:
    rel = geom.wheel_xy_m - icr_xy
    vx, vy = -rel[:, 1] * omega_sign, rel[:, 0] * omega_sign  # direction of z x (p - icr)
    angle = np.arctan2(vy, vx)
    travel = np.hypot(rel[:, 0], rel[:, 1]) * scale
    flip = np.abs(angle) > math.pi / 2 + 1e-9  # steer the short way round, roll backwards
    angle = np.where(flip, angle - math.pi * np.sign(angle), angle)
    travel = np.where(flip, -travel, travel)
    return angle, travel


def plan(primitive: Primitive, geom: RoverGeometry | None = None) -> WheelPlan:
    """Steering and wheel travel for a primitive (pure geometry)."""
    geom = geom or RoverGeometry()
    if isinstance(primitive, Straight):
        sign = 1.0 if primitive.distance_m >= 0 else -1.0
        travel = np.full(len(WHEELS), primitive.distance_m)
        return WheelPlan(np.zeros(len(STEERED)), travel, abs(primitive.distance_m) * sign)
    if isinstance(primitive, Arc):
        R = primitive.radius_m
        if abs(R) < 0.3:
            raise ValueError(f"arc radius {R} m is tighter than the rover allows (|R| >= 0.3 m); use TurnInPlace")
        # angle swept = distance / R; omega sign = sign(distance / R)
        swept = primitive.distance_m / R
        angle, travel = _plan_about_icr(np.array([0.0, R]), math.copysign(1.0, swept), abs(swept), geom)
        return WheelPlan(angle[_STEER_INDEX], travel, primitive.distance_m)
    if isinstance(primitive, TurnInPlace):
        a = primitive.angle_rad
        angle, travel = _plan_about_icr(np.zeros(2), math.copysign(1.0, a), abs(a), geom)
        return WheelPlan(angle[_STEER_INDEX], travel, a)
    raise TypeError(f"unknown drive primitive {primitive!r}")


@dataclass(frozen=True)
class DriveResult:
    primitive: Primitive
    completed: bool  # False if stopped early by the stop callback
    reason: str
    duration_s: float
    wheel_odometry_m: float  # mean absolute rim travel the wheels actually turned


Tick = Callable[[RoverSim], str | None]
"""Called every 8 Hz tick while driving; returning a string stops the drive with that reason."""


def steer(sim: RoverSim, steer_rad: np.ndarray, on_tick: Tick | None = None) -> None:
    """Turn the corner wheels to ``steer_rad`` with the wheels held, waiting until they arrive."""
    sim.hold()
    sim.set_steering_rad(steer_rad)
    t0 = sim.time_s
    while np.abs(sim.steer_angles_rad() - steer_rad).max() > STEER_TOLERANCE_RAD:
        if sim.time_s - t0 > STEER_TIMEOUT_S:
            break  # a wheel jammed against a rock: drive with what we have, as flight software would
        sim.step(None, int(round(TICK_S / sim.timestep_s)))
        if on_tick is not None:
            on_tick(sim)


def execute(
    sim: RoverSim,
    primitive: Primitive,
    speed_m_s: float = NOMINAL_SPEED_M_S,
    on_tick: Tick | None = None,
    geom: RoverGeometry | None = None,
) -> DriveResult:
    """Steer, then roll the wheels through the commanded travel on a trapezoidal profile, then park.

    The fastest wheel moves at ``speed_m_s`` (at most 5 cm/s). ``on_tick`` runs at 8 Hz (sensor collection, VO,
    keep-out checks); if it returns a reason the drive stops there and the wheels are held.
    """
    if not 0 < speed_m_s <= MAX_WHEEL_SPEED_M_S:
        raise ValueError(f"speed_m_s={speed_m_s} outside (0, {MAX_WHEEL_SPEED_M_S}] m/s (MER's peak is 5 cm/s)")
    p = plan(primitive, geom)
    t_start = sim.time_s
    steer(sim, p.steer_rad, on_tick)
    r = sim.law.radius_m
    peak_travel_m = float(np.abs(p.wheel_travel_m).max())
    angles0 = sim.wheel_angles_rad()
    steps_per_tick = int(round(TICK_S / sim.timestep_s))
    tick_s = steps_per_tick * sim.timestep_s
    done_m, v = 0.0, 0.0  # progress of the fastest wheel along its travel, and its current speed
    reason, completed = "commanded wheel travel reached", True
    while peak_travel_m - done_m > 1e-9:
        remaining = peak_travel_m - done_m
        v_brake = math.sqrt(2.0 * ACCEL_M_S2 * remaining)
        v = min(v + ACCEL_M_S2 * tick_s, speed_m_s, max(v_brake, 0.002))
        advance = min(v * tick_s, remaining)
        fraction = advance / peak_travel_m
        rates = p.wheel_travel_m * fraction / (r * tick_s)
        sim.step(rates, steps_per_tick)
        done_m += advance
        if on_tick is not None:
            stop = on_tick(sim)
            if stop:
                reason, completed = stop, False
                break
    sim.hold()
    travelled = float(np.abs(sim.wheel_angles_rad() - angles0).mean() * r)
    return DriveResult(primitive, completed, reason, sim.time_s - t_start, travelled)
