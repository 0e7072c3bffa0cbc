"""Proprioceptive sensors: an LN-200-class IMU, wheel and steering encoders, and the mast pointing helper.

The IMU frame is the rover body frame (the ``imu`` site sits at the body origin with no rotation). The simulated
world does not rotate, so the gyro does not sense Mars's spin (14.6 deg/h); nothing here adds it.

IMU noise model (Litton LN-200 class, REFERENCE.md section 1), stated as continuous densities so any sample rate
gives the same statistics; a sample averaged over ``dt`` has white-noise std ``density / sqrt(dt)``, hence an
Allan deviation ``density / sqrt(tau)`` in the white-noise region:

* gyro angle random walk ``0.07 deg/sqrt(h)`` = 2.04e-5 rad/sqrt(s): after ``T`` seconds the integrated angle has
  std ``ARW * sqrt(T)`` (0.07 deg after 1 h);
* gyro bias instability ``1 deg/h``: a first-order Gauss-Markov bias per axis with that stationary std and a
  ``gyro_bias_corr_time_s`` correlation time (it starts from its stationary distribution, so it is also the
  turn-on bias); the published "drift < 3 deg per hour" is this bias integrated;
* accelerometer white noise ``50 micro-g/sqrt(Hz)``, micro-g of *Earth* gravity, 9.80665e-6 m/s^2 (the unit of the
  datasheet), not Mars g: a 1 s average has 4.9e-4 m/s^2 std, 0.008 deg of tilt at Mars's 3.711 m/s^2;
* an optional accelerometer turn-on bias (off by default).

Encoder model: MER drive motors carry shaft encoders behind a gear train of about 1500:1, so the wheel angle is
resolved to 10^4-10^5 counts per turn; we quantise to ``2**14`` counts per wheel revolution (0.38 mrad, 48 um of
rolling at r = 0.125 m) by truncation as an incremental counter does, and the absolute steering sensors to
``2**12`` counts per turn (0.088 deg) by rounding. Both resolutions are assumptions, not flight numbers.

Odometry and attitude errors (``[sensors.odometry]``, :mod:`rover_sim.scenario.odometry_spec` for the sizes and
sources): :class:`OdometryErrors` draws them once per run from the scenario seed (its own random stream, so the
IMU noise is the same draw with or without them). They are applied where they arise: the IMU measures through
its misaligned, mis-scaled axes (``M = diag(1 + s) R_mis^T``, before bias and noise), the wheel encoders see the
rotation a wheel of the *true* effective radius needed for the rolling the physics did (``angle / (1 + e)``: the
onboard odometry, which keeps the nominal radius, is off by the radius error ``e``), and the steering sensors
read the true angle minus a zero offset. The start-heading error is applied by the world to the operator-given
start pose. All zero (the ideal profile): nothing is drawn or applied.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation

from nav.types import EncoderSample, ImuSample

if TYPE_CHECKING:
    from rover_sim.sim.physics import RoverSim

G0_M_S2 = 9.80665  # standard (Earth) gravity: the g of "micro-g" in accelerometer datasheets
DEG = math.pi / 180.0
TIME_TOL_S = 1e-9  # slack when comparing a sample's due time with the simulation clock


@dataclass(frozen=True)
class OdometryErrors:
    """One run's draw of the odometry and attitude errors (see the module docstring); :meth:`none` is ideal."""

    wheel_angle_scale: np.ndarray | None = None  # (6,) WHEELS order: 1 / (1 + radius error)
    steer_offset_rad: np.ndarray | None = None  # (4,) STEERED order: sensor reading = true - offset
    gyro_matrix: np.ndarray | None = None  # (3, 3): measured = M @ true (misalignment and scale factor)
    accel_matrix: np.ndarray | None = None  # (3, 3)
    heading_error_rad: float = 0.0  # added to the operator-given start heading

    @classmethod
    def none(cls) -> OdometryErrors:
        return cls()

    @classmethod
    def draw(
        cls,
        seed: int,
        wheel_radius_error_pct: float = 0.0,
        steer_offset_deg: float = 0.0,
        imu_misalignment_mrad: float = 0.0,
        gyro_scale_factor_ppm: float = 0.0,
        accel_scale_factor_ppm: float = 0.0,
        heading_error_deg: float = 0.0,
    ) -> OdometryErrors:
        """Seeded 1-sigma Gaussian draws of each term; a zero size draws nothing and leaves the term off."""
        rng = np.random.default_rng([seed, 0x0D0])  # own stream: the IMU noise draw is unchanged
        scale = steer = gyro = accel = None
        if wheel_radius_error_pct > 0:
            scale = 1.0 / (1.0 + rng.normal(0.0, wheel_radius_error_pct / 100.0, 6))
        if steer_offset_deg > 0:
            steer = rng.normal(0.0, math.radians(steer_offset_deg), 4)
        if imu_misalignment_mrad > 0 or gyro_scale_factor_ppm > 0 or accel_scale_factor_ppm > 0:
            R_mis = Rotation.from_rotvec(rng.normal(0.0, imu_misalignment_mrad * 1e-3, 3)).as_matrix()
            gyro = np.diag(1.0 + rng.normal(0.0, gyro_scale_factor_ppm * 1e-6, 3)) @ R_mis.T
            accel = np.diag(1.0 + rng.normal(0.0, accel_scale_factor_ppm * 1e-6, 3)) @ R_mis.T
        heading = math.radians(rng.normal(0.0, heading_error_deg)) if heading_error_deg > 0 else 0.0
        return cls(scale, steer, gyro, accel, heading)


@dataclass(frozen=True)
class ImuParams:
    """LN-200-class IMU error model; see the module docstring for the meaning and units of each term."""

    rate_hz: float = 100.0
    gyro_arw_deg_sqrt_h: float = 0.07
    gyro_bias_instability_deg_h: float = 1.0
    gyro_bias_corr_time_s: float = 600.0  # our choice: wanders over minutes (Allan bump near 1.9 x 600 s)
    accel_noise_ug_sqrt_hz: float = 50.0
    accel_bias_ug: float = 0.0  # std of a constant turn-on bias per axis (0: none)

    @property
    def gyro_white_rad_sqrt_s(self) -> float:
        return self.gyro_arw_deg_sqrt_h * DEG / 60.0  # 1/sqrt(h) = 1/(60 sqrt(s))

    @property
    def gyro_bias_rad_s(self) -> float:
        return self.gyro_bias_instability_deg_h * DEG / 3600.0

    @property
    def accel_white_m_s2_sqrt_hz(self) -> float:
        return self.accel_noise_ug_sqrt_hz * 1e-6 * G0_M_S2

    def __post_init__(self) -> None:
        if self.rate_hz <= 0 or self.gyro_bias_corr_time_s <= 0:
            raise ValueError("rate_hz and gyro_bias_corr_time_s must be positive")


class ImuModel:
    """Adds LN-200-class errors to true body rates and specific forces; stateful (the gyro bias wanders)."""

    def __init__(self, params: ImuParams | None = None, seed: int = 0, errors: OdometryErrors | None = None) -> None:
        self.params = params or ImuParams()
        self.errors = errors or OdometryErrors.none()
        self._rng = np.random.default_rng(seed)
        p = self.params
        self.gyro_bias_rad_s = self._rng.normal(0.0, p.gyro_bias_rad_s, 3)  # stationary start
        self.accel_bias_m_s2 = self._rng.normal(0.0, p.accel_bias_ug * 1e-6 * G0_M_S2, 3)
        self._last_t_s: float | None = None

    def corrupt(
        self, dt_s: float, gyro_true_rad_s: np.ndarray, accel_true_m_s2: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Measurements for ``N`` consecutive samples ``dt_s`` apart: arrays ``(N, 3)`` in, ``(N, 3)`` out."""
        p, rng = self.params, self._rng
        gyro_true = np.atleast_2d(np.asarray(gyro_true_rad_s, dtype=float))
        accel_true = np.atleast_2d(np.asarray(accel_true_m_s2, dtype=float))
        n = len(gyro_true)
        if self.errors.gyro_matrix is not None:  # the IMU senses along its own (misaligned, mis-scaled) axes
            gyro_true = gyro_true @ self.errors.gyro_matrix.T
        if self.errors.accel_matrix is not None:
            accel_true = accel_true @ self.errors.accel_matrix.T
        phi = math.exp(-dt_s / p.gyro_bias_corr_time_s)
        drive = rng.standard_normal((n, 3)) * (p.gyro_bias_rad_s * math.sqrt(1.0 - phi * phi))
        bias, _ = lfilter([1.0], [1.0, -phi], drive, axis=0, zi=(phi * self.gyro_bias_rad_s)[None, :])
        self.gyro_bias_rad_s = bias[-1].copy()
        gyro = gyro_true + bias + rng.standard_normal((n, 3)) * (p.gyro_white_rad_sqrt_s / math.sqrt(dt_s))
        accel_noise = rng.standard_normal((n, 3)) * (p.accel_white_m_s2_sqrt_hz / math.sqrt(dt_s))
        accel = accel_true + self.accel_bias_m_s2 + accel_noise
        return gyro, accel

    def measure(self, t_s: float, gyro_true_rad_s: np.ndarray, accel_true_m_s2: np.ndarray) -> ImuSample:
        """One sample at ``t_s``; its noise covers the interval since the previous sample (1/rate for the first)."""
        dt = 1.0 / self.params.rate_hz if self._last_t_s is None else t_s - self._last_t_s
        if dt <= 0.0:
            raise ValueError(f"IMU samples must move forward in time (t={t_s}, previous {self._last_t_s})")
        self._last_t_s = t_s
        gyro, accel = self.corrupt(dt, gyro_true_rad_s, accel_true_m_s2)
        return ImuSample(t_s=t_s, gyro_rad_s=gyro[0], accel_m_s2=accel[0])

    def measure_many(self, t_s: list[float], gyro_true_rad_s: np.ndarray, accel_true_m_s2: np.ndarray) -> list:
        """:meth:`measure` for consecutive samples at once, number for number: each sample draws its noise in the
        same order (bias drive, gyro white, accel white) and the bias recursion is the same arithmetic as
        ``corrupt``'s one-sample ``lfilter``, so the result equals one :meth:`measure` call per sample (the
        sensor suite corrupts the samples of a tick in one go, off the physics loop)."""
        n = len(t_s)
        if n == 0:
            return []
        p = self.params
        dts = []
        last = self._last_t_s
        for t in t_s:
            dt = 1.0 / p.rate_hz if last is None else t - last
            if dt <= 0.0:
                raise ValueError(f"IMU samples must move forward in time (t={t}, previous {last})")
            dts.append(dt)
            last = t
        self._last_t_s = last
        gyro_true = np.asarray(gyro_true_rad_s, dtype=float).reshape(n, 3)
        accel_true = np.asarray(accel_true_m_s2, dtype=float).reshape(n, 3)
        if self.errors.gyro_matrix is not None:  # row by row: the same product as one sample at a time
            gyro_true = np.concatenate([g[None, :] @ self.errors.gyro_matrix.T for g in gyro_true])
        if self.errors.accel_matrix is not None:
            accel_true = np.concatenate([a[None, :] @ self.errors.accel_matrix.T for a in accel_true])
        z = self._rng.standard_normal((n, 3, 3))  # per sample: bias drive, gyro white, accel white
        zb = z[:, 0].tolist()
        bias = np.empty((n, 3))
        b0, b1, b2 = self.gyro_bias_rad_s.tolist()
        for k in range(n):
            phi = math.exp(-dts[k] / p.gyro_bias_corr_time_s)
            scale = p.gyro_bias_rad_s * math.sqrt(1.0 - phi * phi)
            d0, d1, d2 = zb[k]
            b0, b1, b2 = d0 * scale + phi * b0, d1 * scale + phi * b1, d2 * scale + phi * b2
            bias[k] = (b0, b1, b2)
        self.gyro_bias_rad_s = bias[-1].copy()
        root_dt = np.array([math.sqrt(dt) for dt in dts])[:, None]
        gyro = gyro_true + bias + z[:, 1] * (p.gyro_white_rad_sqrt_s / root_dt)
        accel = accel_true + self.accel_bias_m_s2 + z[:, 2] * (p.accel_white_m_s2_sqrt_hz / root_dt)
        return [ImuSample(t_s=t, gyro_rad_s=g, accel_m_s2=a) for t, g, a in zip(t_s, gyro, accel, strict=True)]


@dataclass(frozen=True)
class EncoderParams:
    """Wheel and steering encoder resolution and sampling rate (see the module docstring)."""

    rate_hz: float = 8.0  # MER updated its onboard pose at 8 Hz
    wheel_counts_per_rev: int = 2**14
    steer_counts_per_rev: int = 2**12

    @property
    def wheel_quantum_rad(self) -> float:
        return 2.0 * math.pi / self.wheel_counts_per_rev

    @property
    def steer_quantum_rad(self) -> float:
        return 2.0 * math.pi / self.steer_counts_per_rev


class EncoderModel:
    """Quantised wheel (cumulative, truncated to whole counts) and steering (rounded) angles."""

    def __init__(self, params: EncoderParams | None = None, errors: OdometryErrors | None = None) -> None:
        self.params = params or EncoderParams()
        self.errors = errors or OdometryErrors.none()

    def measure(self, t_s: float, wheel_angle_rad: np.ndarray, steer_angle_rad: np.ndarray) -> EncoderSample:
        p, e = self.params, self.errors
        if e.wheel_angle_scale is not None:  # the effective radius differs from the nominal one
            wheel_angle_rad = np.asarray(wheel_angle_rad, dtype=float) * e.wheel_angle_scale
        if e.steer_offset_rad is not None:  # the steering sensor's zero is off
            steer_angle_rad = np.asarray(steer_angle_rad, dtype=float) - e.steer_offset_rad
        wheel = np.floor(np.asarray(wheel_angle_rad, dtype=float) / p.wheel_quantum_rad) * p.wheel_quantum_rad
        steer = np.rint(np.asarray(steer_angle_rad, dtype=float) / p.steer_quantum_rad) * p.steer_quantum_rad
        return EncoderSample(t_s=t_s, wheel_angle_rad=wheel, steer_angle_rad=steer)


class SensorSuite:
    """The rover's IMU and encoders, sampled inside the physics loop at their own rates.

    On construction the suite registers itself as ``sim``'s sub-step hook, called every
    :attr:`steps_per_imu_sample` physics steps (``RoverSim.set_substep_hook``), so IMU samples keep their rate
    however long the runner's physics chunks are; encoders are read on the first IMU tick at or after each
    encoder due time. The runner drains the buffers with :meth:`poll`. One sample of each is taken at
    construction (the encoder baseline). ``attach=False`` leaves the hook alone: call :meth:`sample` yourself
    every IMU period.
    """

    def __init__(
        self,
        sim: RoverSim,
        seed: int = 0,
        imu: ImuParams | None = None,
        encoders: EncoderParams | None = None,
        attach: bool = True,
        errors: OdometryErrors | None = None,
    ) -> None:
        self.sim = sim
        self.errors = errors or OdometryErrors.none()
        self.imu = ImuModel(imu, seed, self.errors)
        self.encoders = EncoderModel(encoders, self.errors)
        self.steps_per_imu_sample = max(1, int(round(1.0 / (self.imu.params.rate_hz * sim.timestep_s))))
        self._imu: list[ImuSample] = []
        self._raw_t: list[float] = []  # IMU samples taken but not yet corrupted (see poll)
        self._raw_imu: list[tuple[np.ndarray, np.ndarray]] = []
        self._enc: list[EncoderSample] = []
        self._next_enc_t = -math.inf
        self.sample(sim)
        if attach:
            sim.set_substep_hook(self.sample, self.steps_per_imu_sample)

    @property
    def imu_period_s(self) -> float:
        """Actual IMU sample period: a whole number of physics steps (10 ms at the 5 ms default step)."""
        return self.steps_per_imu_sample * self.sim.timestep_s

    def sample(self, sim: RoverSim) -> None:
        """Take one IMU sample now, and an encoder sample if one is due."""
        t = sim.time_s
        gyro, accel = sim.imu_raw()
        self._raw_t.append(t)  # corrupted in one batch when polled (ImuModel.measure_many: the same numbers)
        self._raw_imu.append((gyro, accel))
        if t + TIME_TOL_S >= self._next_enc_t:
            self._enc.append(self.encoders.measure(t, sim.wheel_angles_rad(), sim.steer_angles_rad()))
            period = 1.0 / self.encoders.params.rate_hz
            nxt = self._next_enc_t + period  # keep the schedule ...
            self._next_enc_t = nxt if nxt > t + TIME_TOL_S else t + period  # ... unless it fell behind

    def poll(self) -> tuple[list[ImuSample], list[EncoderSample]]:
        """All samples taken since the previous call, oldest first: (IMU samples, encoder samples)."""
        self._flush_imu()
        imu, enc = self._imu, self._enc
        self._imu, self._enc = [], []
        return imu, enc

    def _flush_imu(self) -> None:
        if self._raw_t:
            raw = np.array(self._raw_imu)  # (n, 2, 3): true gyro, true specific force
            self._imu.extend(self.imu.measure_many(self._raw_t, raw[:, 0], raw[:, 1]))
            self._raw_t, self._raw_imu = [], []

    def detach(self) -> None:
        """Stop sampling inside the physics loop."""
        self.sim.set_substep_hook(None)


def roll_pitch_from_accel(accel_m_s2: np.ndarray) -> tuple[float, float]:
    """Roll and pitch (rad, ZYX Euler) of the body from a specific-force reading at rest (gravity only)."""
    ax, ay, az = np.asarray(accel_m_s2, dtype=float)
    return float(math.atan2(ay, az)), float(math.atan2(-ax, math.hypot(ay, az)))


def tilt_from_accel_deg(accel_m_s2: np.ndarray) -> float:
    """Angle between the body z axis and the vertical, from a specific-force reading at rest."""
    a = np.asarray(accel_m_s2, dtype=float)
    return float(np.degrees(np.arccos(np.clip(a[2] / np.linalg.norm(a), -1.0, 1.0))))


def point_mast(sim: RoverSim, pan_rad: float, tilt_rad: float, settle_s: float = 2.0) -> np.ndarray:
    """Command the navcam mast to (pan, tilt), let it settle for ``settle_s`` with the wheels parked.

    Returns the achieved (pan, tilt) in rad (the mast servo tracks to about 1e-5 rad in 2 s). Positive tilt
    pitches the cameras down (rotation about the rover's +y axis). Camera extrinsics must be re-read afterwards.
    """
    m = sim.model
    for joint, value in (("mast_pan", pan_rad), ("mast_tilt", tilt_rad)):
        lo, hi = m.jnt_range[m.joint(joint).id]
        if not lo <= value <= hi:
            raise ValueError(f"{joint} = {value:.3f} rad is outside its range [{lo:.2f}, {hi:.2f}] (rover.xml)")
    sim.hold()
    sim.set_mast(pan_rad, tilt_rad)
    sim.step_for(settle_s)
    return sim.mast_angles_rad()
