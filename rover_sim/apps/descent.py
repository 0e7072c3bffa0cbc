"""The DIMES descent scenario: a MER lander on its parachute over a cratered plain, three descent images.

What is simulated (REFERENCE.md section 6; Maimone et al., "Autonomous Navigation Results from the MER Mission",
section 2): the lander hangs under the parachute and backshell, the wind carries it sideways, the parachute system
swings, and a downward camera takes three images at about 2000 m, 1700 m and 1400 m above the ground, about 4 s
apart. The IMU gives attitude and the velocity/position change since the first image, the radar altimeter the
height above the ground. :func:`simulate_descent` returns the sensor data as :class:`nav.dimes.DescentImage`
frames (what the flight software saw) and, separately, the :class:`DescentTruth`; the estimator never sees the
latter.

* **Terrain** (:class:`DescentTerrainSpec`, :func:`descent_terrain`): a 3.2 km square plain at 4 m cells with
  craters of 20-500 m (cumulative size-frequency ``N(>D) ~ D^-2``, fresh to degraded depth/diameter 0.06-0.2),
  fBm roughness, and a material map whose outcrop (crater walls) and patches of darker ground give albedo
  variation. ``terrains.TerrainRecipe`` caps a patch at 2 km and a cell at 2 m, so the recipe is synthesised at
  scale ``1/s`` (``s = 2`` by default) and scaled up by ``s`` in all three axes: geometric similarity, exact for
  the craters (depth/diameter ratios and slopes are scale-free) and the fBm roughness.
* **Appearance** (:func:`descent_texture`): ``terrains.albedo_texture`` (its centimetre-scale sand and bedrock
  detail averages out at 1.6 m texels; the material patches remain) plus a multi-scale albedo mottling of
  ``mottle_contrast`` (dust and sand sheets at 15-250 m), one 2048 px texture (MuJoCo/GL side limit: keep
  ``texture_px`` <= 8192) draped over the heightfield.
* **Camera** (:class:`DescentCameraConfig`; the scene and renderer are in :mod:`rover_sim.apps.descent_scene`):
  the MER descent imager had a 45 deg field of view and a 1024x1024 detector; DIMES used the images binned to
  256x256. We render 256x256 directly by default (GL mipmapping averages the texture; ``binning=4`` renders 1024x1024
  and averages 4x4 blocks like the detector, 4-5x slower), convert to luminance and add 12-bit read noise and
  quantisation (:mod:`rover_sim.render.renderer`). MuJoCo scales the clip planes by ``statistic/extent``: extent
  1000 m with ``znear=0.01``, ``zfar=10`` gives 10 m to 10 km.
* **Kinematics** (:class:`DescentTrajectory`, scripted, not a physics test): the pendulum pivot (parachute
  riser confluence on the backshell) falls at ``descent_rate_mps`` (about 75 m/s) and drifts with the wind, which
  changes with height (shear); the lander hangs ``bridle_m`` below it, so the pendulum swing (a few deg, period
  ``2 pi sqrt(L/g)``) both tilts the camera and moves it sideways; a faster wobble of the lander on its bridle and a
  slow spin about the vertical complete the attitude motion (a few deg/s).
* **Sensors**: an LN-200-class IMU reports attitude (alignment error ``imu_attitude_bias_deg`` per axis, gyro
  drift, white noise) and the velocity and position changes since the first image in the local-level frame
  (accelerometer bias plus the gravity leak of the attitude error); the radar altimeter reports the height above
  the ground under the lander with a scale error and white noise. All error sizes are assumptions stated on
  :class:`DescentConditions`, not flight numbers.

Frames: world (local level) x east, y north, z up, origin at the patch centre; camera frames are OpenCV (x right,
y down, z forward), lander body z up (toward the parachute), the camera looking along body -z.

GL: one :class:`DescentRenderer` owns one EGL context; never ``fork()`` after it exists.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from nav.camera import PinholeCamera
from nav.dimes import DescentImage
from nav.geometry import so3_exp
from rover_sim.apps.descent_scene import DescentCameraConfig, DescentRenderer
from rover_sim.render.config import ImageNoise
from rover_sim.sim.assembly import Sun
from terrains import (
    CraterSpec,
    MaterialSpec,
    RockSpec,
    RoughnessSpec,
    Terrain,
    TerrainRecipe,
    albedo_texture,
    synthesize,
    texture_rgb_u8,
)
from terrains._noise import layer_rng, smooth_noise

MARS_G_MPS2 = 3.711
DEG = math.pi / 180.0
IMAGE_ALTITUDES_M: tuple[float, float, float] = (2000.0, 1700.0, 1400.0)  # MER: about 2000, 1700, 1400 m
MAX_TEXTURE_PX = 8192  # GL texture side limit we allow (llvmpipe accepts 16384; most GPUs 8192-16384)
RECIPE_MAX_SIZE_M = 2000.0  # terrains.TerrainRecipe limits: patch side ...
RECIPE_MAX_CELL_M = 2.0  # ... grid cell ...
RECIPE_MAX_ROUGHNESS_M = 0.5  # ... and roughness rms


class _Part:
    """Stable generator keys of the scenario's random draws (``layer_rng(seed, key)``). Never renumber."""

    CRATERS = 101
    MOTTLE = 102
    CONDITIONS = 103
    SENSORS = 104


# --------------------------------------------------------------------------------------------------- terrain


@dataclass(frozen=True)
class DescentTerrainSpec:
    """A kilometre-scale landing-site plain as the descent camera sees it (lengths in metres)."""

    size_m: float = 3200.0  # square patch; covers the 45 deg view from 2000 m with swing, spin and drift
    cell_size_m: float = 4.0  # heightfield spacing (a 256^2 image pixel is 4.5-6.5 m on the ground)
    crater_count: int = 150  # craters of diameter >= crater_diameter_m[0] on the patch
    crater_diameter_m: tuple[float, float] = (20.0, 500.0)
    crater_sfd_exponent: float = 2.0  # cumulative size-frequency N(>D) ~ D^-exponent (small Mars craters ~2)
    depth_to_diameter: tuple[float, float] = (0.06, 0.2)  # degraded ... fresh (Pike: 0.2)
    rim_height_frac: tuple[float, float] = (0.01, 0.036)  # of D (Pike: 0.036 fresh)
    roughness_rms_m: float = 1.0
    roughness_correlation_m: float = 200.0
    bedrock_fraction: float = 0.1  # darker outcrop patches (material albedo 0.46 vs sand 0.58)
    mixed_fraction: float = 0.15
    patch_scale_m: float = 30.0
    outcrop_slope_deg: float = 18.0  # steeper crater walls are bedrock (darker)
    mottle_contrast: float = 0.03  # std of each octave of the albedo mottling added to the material albedo
    mottle_scales_m: tuple[float, ...] = (15.0, 60.0, 250.0)
    texture_px: int = 2048  # texture side; 1.6 m texels on 3.2 km
    featureless: bool = False  # uniform sand material with no albedo detail (set crater_count=0 too)

    def __post_init__(self) -> None:
        if not 0 < self.texture_px <= MAX_TEXTURE_PX:
            raise ValueError(f"texture_px must be in 1..{MAX_TEXTURE_PX} (GL texture limit), got {self.texture_px}")
        lo, hi = self.crater_diameter_m
        if not 0.0 < lo <= hi:
            raise ValueError(f"crater_diameter_m must be (lo, hi) with 0 < lo <= hi, got {self.crater_diameter_m}")

    @property
    def recipe_scale(self) -> float:
        """Factor ``s`` by which the recipe is shrunk to fit ``terrains.TerrainRecipe``'s limits."""
        return max(
            1.0,
            self.size_m / RECIPE_MAX_SIZE_M,
            self.cell_size_m / RECIPE_MAX_CELL_M,
            self.roughness_rms_m / RECIPE_MAX_ROUGHNESS_M,
        )


#: Meridiani-like plain: no craters, uniform fine sand, only a kilometre-scale brightness undulation (shading-free
#: gradients, nothing with 2-D structure at template scale): DIMES must decline to estimate.
FEATURELESS_TERRAIN = DescentTerrainSpec(
    featureless=True, crater_count=0, roughness_rms_m=0.2, mottle_contrast=0.03, mottle_scales_m=(1000.0,)
)


def crater_population(spec: DescentTerrainSpec, seed: int) -> list[tuple[float, float, float, float, float]]:
    """``(x_m, y_m, diameter_m, depth_to_diameter, rim_height_frac)`` of each crater, physical units.

    Diameters follow a truncated power law (cumulative ``N(>D) ~ D^-b`` between the two bounds), centres are
    uniform over the patch.
    """
    if spec.featureless or spec.crater_count == 0:
        return []
    rng = layer_rng(seed, _Part.CRATERS)
    n, b = spec.crater_count, spec.crater_sfd_exponent
    d_lo, d_hi = spec.crater_diameter_m
    u = rng.uniform(size=n)
    diameters = d_lo * (1.0 - u * (1.0 - (d_lo / d_hi) ** b)) ** (-1.0 / b)
    xy = rng.uniform(-0.5 * spec.size_m, 0.5 * spec.size_m, size=(n, 2))
    depth = rng.uniform(*spec.depth_to_diameter, size=n)
    rim = rng.uniform(*spec.rim_height_frac, size=n)
    return [(float(xy[i, 0]), float(xy[i, 1]), float(diameters[i]), float(depth[i]), float(rim[i])) for i in range(n)]


def descent_recipe(spec: DescentTerrainSpec, seed: int) -> TerrainRecipe:
    """The ``terrains`` recipe of the plain at scale ``1 / spec.recipe_scale`` (see :func:`descent_terrain`)."""
    s = spec.recipe_scale
    craters = [
        CraterSpec(center_xy_m=(x / s, y / s), diameter_m=d / s, depth_to_diameter=dd, rim_height_frac=rim)
        for x, y, d, dd, rim in crater_population(spec, seed)
    ]
    material = (
        MaterialSpec(kind="sand")
        if spec.featureless
        else MaterialSpec(
            kind="patches",
            bedrock_fraction=spec.bedrock_fraction,
            mixed_fraction=spec.mixed_fraction,
            patch_scale_m=spec.patch_scale_m / s,
            outcrop_slope_deg=spec.outcrop_slope_deg,
        )
    )
    return TerrainRecipe(
        size_m=(spec.size_m / s, spec.size_m / s),
        cell_size_m=spec.cell_size_m / s,
        craters=craters,
        roughness=RoughnessSpec(
            rms_m=spec.roughness_rms_m / s, correlation_length_m=spec.roughness_correlation_m / s, octaves=6
        ),
        rocks=RockSpec(cover_fraction=0.0),  # metre-scale rocks are sub-pixel from 1400 m
        material=material,
    )


def descent_terrain(spec: DescentTerrainSpec | None = None, seed: int = 0) -> Terrain:
    """Synthesise the plain: ``synthesize(recipe at 1/s)`` scaled up by ``s`` in x, y and z (similarity)."""
    spec = spec or DescentTerrainSpec()
    s = spec.recipe_scale
    small = synthesize(descent_recipe(spec, seed), seed)
    return Terrain(small.heights_m * s, small.cell_size_m * s, small.materials, seed=seed)


def descent_texture(terrain: Terrain, spec: DescentTerrainSpec | None = None, seed: int = 0) -> np.ndarray:
    """``(N, N, 3)`` uint8 albedo texture (``terrains`` layout: row 0 south, column 0 west), ``N = texture_px``."""
    spec = spec or DescentTerrainSpec()
    px_per_m = spec.texture_px / (2.0 * terrain.half_x_m)
    if spec.featureless:
        albedo = albedo_texture(terrain, px_per_m, seed, fine_soil=True, contrast=0.0)
    else:
        albedo = albedo_texture(terrain, px_per_m, seed)
    rng = layer_rng(seed, _Part.MOTTLE)
    for scale_m in spec.mottle_scales_m:
        albedo = albedo + spec.mottle_contrast * smooth_noise(albedo.shape, scale_m * px_per_m, rng)
    return texture_rgb_u8(np.clip(albedo, 0.0, 1.0))


# ---------------------------------------------------------------------------------------------- conditions


@dataclass(frozen=True)
class DescentConditions:
    """Everything random about one descent except the terrain: wind, swing, sensors, lighting.

    Error sizes (1 sigma) and ranges are assumptions chosen for an LN-200-class IMU and a radar altimeter, not
    flight numbers; see the field comments.
    """

    wind_mps: np.ndarray  # (2,) horizontal wind at the second image's altitude (1700 m)
    wind_shear_mps_per_km: np.ndarray  # (2,) wind change per km of height: the drift accelerates as we descend
    descent_rate_mps: float  # vertical speed of the parachute system (MER: about 75 m/s)
    bridle_m: float  # pendulum length, parachute riser confluence to lander
    swing_amplitude_rad: np.ndarray  # (2,) pendulum amplitude about world x and y
    swing_phase_rad: np.ndarray  # (2,)
    wobble_amplitude_rad: np.ndarray  # (2,) faster rocking of the lander on its bridle
    wobble_period_s: float
    wobble_phase_rad: np.ndarray  # (2,)
    yaw0_rad: float
    yaw_rate_rad_s: float  # slow spin under the parachute swivel
    ground_offset_m: np.ndarray  # (2,) ground point under the lander at the second image (patch frame)
    sun: Sun
    # IMU: a constant attitude error (alignment at parachute deploy + camera/IMU misalignment), gyro drift,
    # white attitude noise per image; accelerometer bias (plus the gravity leak of the attitude error).
    imu_attitude_bias_rad: np.ndarray  # (3,) world-frame rotation vector
    imu_gyro_drift_rad_s: np.ndarray  # (3,)
    imu_attitude_noise_rad: float  # per-axis std of the white attitude noise per image
    imu_accel_bias_mps2: np.ndarray  # (3,)
    # Radar altimeter: a scale error constant over the descent plus white noise per measurement.
    radar_scale_error: float
    radar_noise_m: float
    noise_seed: int  # sensor white noise and image read noise

    @property
    def swing_period_s(self) -> float:
        """Pendulum period ``2 pi sqrt(L / g)`` on Mars."""
        return 2.0 * math.pi * math.sqrt(self.bridle_m / MARS_G_MPS2)

    @staticmethod
    def sample(
        seed: int,
        max_wind_mps: float = 20.0,
        *,
        max_shear_mps_per_km: float = 4.0,
        max_swing_deg: float = 4.0,
        max_wobble_deg: float = 1.0,
        max_yaw_rate_deg_s: float = 3.0,
        max_ground_offset_m: float = 50.0,
    ) -> DescentConditions:
        """Random conditions: wind speed uniform in ``[0, max_wind_mps]`` from a uniform direction, and so on."""
        rng = layer_rng(seed, _Part.CONDITIONS)

        def direction() -> np.ndarray:
            a = rng.uniform(0.0, 2.0 * math.pi)
            return np.array([math.cos(a), math.sin(a)])

        wind = rng.uniform(0.0, max_wind_mps) * direction()
        shear = rng.uniform(0.0, max_shear_mps_per_km) * direction()
        sun = Sun(
            azimuth_deg=float(rng.uniform(0.0, 360.0)), elevation_deg=float(rng.uniform(35.0, 65.0)), shadows=False
        )
        return DescentConditions(
            wind_mps=wind,
            wind_shear_mps_per_km=shear,
            descent_rate_mps=float(rng.uniform(70.0, 80.0)),
            bridle_m=float(rng.uniform(25.0, 35.0)),
            swing_amplitude_rad=rng.uniform(0.0, max_swing_deg, 2) * DEG,
            swing_phase_rad=rng.uniform(0.0, 2.0 * math.pi, 2),
            wobble_amplitude_rad=rng.uniform(0.0, max_wobble_deg, 2) * DEG,
            wobble_period_s=float(rng.uniform(2.0, 4.0)),
            wobble_phase_rad=rng.uniform(0.0, 2.0 * math.pi, 2),
            yaw0_rad=float(rng.uniform(0.0, 2.0 * math.pi)),
            yaw_rate_rad_s=float(rng.uniform(-max_yaw_rate_deg_s, max_yaw_rate_deg_s)) * DEG,
            ground_offset_m=rng.uniform(-max_ground_offset_m, max_ground_offset_m, 2),
            sun=sun,
            imu_attitude_bias_rad=rng.normal(0.0, 0.1, 3) * DEG,  # 0.1 deg per axis
            imu_gyro_drift_rad_s=rng.normal(0.0, 1.0, 3) * DEG / 3600.0,  # LN-200: 1 deg/h
            imu_attitude_noise_rad=0.01 * DEG,
            imu_accel_bias_mps2=rng.normal(0.0, 300e-6 * 9.80665, 3),  # 300 micro-g
            radar_scale_error=float(rng.normal(0.0, 0.002)),  # 0.2 %
            radar_noise_m=2.0,
            noise_seed=int(rng.integers(0, 2**31)),
        )


# -------------------------------------------------------------------------------------------- kinematics


@dataclass(frozen=True)
class DescentTrajectory:
    """Scripted lander motion; ``t = 0`` at the first image. Positions in the patch frame (datum z = 0)."""

    conditions: DescentConditions
    altitudes_m: tuple[float, ...] = IMAGE_ALTITUDES_M

    @property
    def image_times_s(self) -> np.ndarray:
        """Times at which the lander passes the image altitudes (above the datum, pendulum sag aside)."""
        return (self.altitudes_m[0] - np.asarray(self.altitudes_m)) / self.conditions.descent_rate_mps

    def _pivot_m(self, t: float) -> np.ndarray:
        c = self.conditions
        t_ref = float(self.image_times_s[1])
        dt = t - t_ref
        # pivot height z(t) = z_ref - rate dt, wind w(z) = w_ref + shear (z - z_ref) / 1000 -> integrate in t
        xy = c.ground_offset_m + c.wind_mps * dt - c.wind_shear_mps_per_km * c.descent_rate_mps * dt * dt / 2000.0
        z = self.altitudes_m[0] + c.bridle_m - c.descent_rate_mps * t
        return np.array([xy[0], xy[1], z])

    def _swing(self, t: float) -> np.ndarray:
        c = self.conditions
        return c.swing_amplitude_rad * np.sin(2.0 * math.pi * t / c.swing_period_s + c.swing_phase_rad)

    def R_world_body(self, t: float) -> np.ndarray:
        """Lander attitude: pendulum swing, then wobble, then spin (body z up toward the parachute)."""
        c = self.conditions
        wobble = c.wobble_amplitude_rad * np.sin(2.0 * math.pi * t / c.wobble_period_s + c.wobble_phase_rad)
        yaw = c.yaw0_rad + c.yaw_rate_rad_s * t
        Rz = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
        swing = self._swing(t)
        return so3_exp(np.array([swing[0], swing[1], 0.0])) @ so3_exp(np.array([wobble[0], wobble[1], 0.0])) @ Rz

    def R_world_cam(self, t: float) -> np.ndarray:
        """Camera attitude (OpenCV axes): x along body x, y along body -y, z (optical axis) along body -z."""
        return self.R_world_body(t) @ np.diag([1.0, -1.0, -1.0])

    def position_m(self, t: float) -> np.ndarray:
        """Lander (= camera) position: the pivot plus the bridle hanging along the swing's -z."""
        swing = self._swing(t)
        down = so3_exp(np.array([swing[0], swing[1], 0.0])) @ np.array([0.0, 0.0, -1.0])
        return self._pivot_m(t) + self.conditions.bridle_m * down

    def velocity_mps(self, t: float, h_s: float = 1e-3) -> np.ndarray:
        """Velocity by a central difference of the analytic position (error ~1e-6 m/s)."""
        return (self.position_m(t + h_s) - self.position_m(t - h_s)) / (2.0 * h_s)


# ----------------------------------------------------------------------------------------------- scenario


@dataclass(frozen=True)
class DescentTruth:
    """Ground truth of one descent (for evaluation only; never given to the estimator)."""

    times_s: np.ndarray  # (3,)
    positions_m: np.ndarray  # (3, 3) lander position at each image
    velocities_mps: np.ndarray  # (3, 3) lander velocity at each image
    R_world_cam: np.ndarray  # (3, 3, 3) true camera attitude at each image
    altitudes_agl_m: np.ndarray  # (3,) true height above the ground under the lander

    @property
    def horizontal_velocity_mps(self) -> np.ndarray:
        """True horizontal velocity at the last image: what DIMES estimates."""
        return self.velocities_mps[-1, :2].copy()


@dataclass(frozen=True)
class DescentRun:
    """One simulated descent: the sensor frames DIMES gets, the truth, the conditions."""

    frames: tuple[DescentImage, ...]
    truth: DescentTruth
    conditions: DescentConditions
    terrain_seed: int
    meta: dict = field(default_factory=dict)


def imu_attitude(conditions: DescentConditions, R_true: np.ndarray, t_s: float, rng: np.random.Generator) -> np.ndarray:
    """IMU attitude of the camera: the true one rotated by bias + drift * t + white noise (world frame)."""
    c = conditions
    err = c.imu_attitude_bias_rad + c.imu_gyro_drift_rad_s * t_s + rng.normal(0.0, c.imu_attitude_noise_rad, 3)
    return so3_exp(err) @ R_true


def imu_accel_error_mps2(conditions: DescentConditions) -> np.ndarray:
    """Constant acceleration error in the local-level frame: bias plus gravity leak of the attitude error.

    Under the parachute the specific force is about ``g`` along the vertical; a tilt error ``e`` (rotation vector)
    resolves it into a horizontal error ``g * (e x z)``.
    """
    leak = MARS_G_MPS2 * np.cross(conditions.imu_attitude_bias_rad, [0.0, 0.0, 1.0])
    return conditions.imu_accel_bias_mps2 + leak


def simulate_descent(
    conditions: DescentConditions,
    terrain: Terrain,
    renderer: DescentRenderer,
    *,
    terrain_seed: int = 0,
) -> DescentRun:
    """Fly the scripted descent over ``terrain`` and take the three images with their IMU and radar data."""
    traj = DescentTrajectory(conditions)
    times = traj.image_times_s
    rng = np.random.default_rng(conditions.noise_seed)
    cam = renderer.config.camera()
    half = min(terrain.half_x_m, terrain.half_y_m)
    acc_err = imu_accel_error_mps2(conditions)
    p0, v0 = traj.position_m(0.0), traj.velocity_mps(0.0)

    frames, pos, vel, rot, agl = [], [], [], [], []
    for k, t in enumerate(times):
        t = float(t)
        p, v, R = traj.position_m(t), traj.velocity_mps(t), traj.R_world_cam(t)
        footprint = ground_footprint_m(cam, R, p)
        if np.abs(footprint).max() > half:
            raise ValueError(
                f"image {k}: the camera sees beyond the {2 * half:.0f} m terrain patch "
                f"(footprint reaches {np.abs(footprint).max():.0f} m); enlarge DescentTerrainSpec.size_m"
            )
        height = float(p[2] - terrain.height_at(p[0], p[1]))
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, p
        image = renderer.render(
            T, conditions.sun, ImageNoise(renderer.config.read_noise_dn12, conditions.noise_seed + k)
        )
        dv = v - v0 + acc_err * t
        dp = p - p0 - v0 * t + 0.5 * acc_err * t * t
        radar = height * (1.0 + conditions.radar_scale_error) + rng.normal(0.0, conditions.radar_noise_m)
        frames.append(
            DescentImage(
                t_s=t,
                image=image,
                camera=cam,
                R_world_cam=imu_attitude(conditions, R, t, rng),
                altitude_m=float(radar),
                imu_delta_v_mps=dv,
                imu_delta_p_m=dp,
            )
        )
        pos.append(p)
        vel.append(v)
        rot.append(R)
        agl.append(height)
    truth = DescentTruth(np.asarray(times), np.array(pos), np.array(vel), np.array(rot), np.array(agl))
    return DescentRun(tuple(frames), truth, conditions, terrain_seed)


def ground_footprint_m(cam: PinholeCamera, R_world_cam: np.ndarray, position_m: np.ndarray) -> np.ndarray:
    """(4, 2) ground points (datum plane z = 0) seen by the image corners."""
    w, h = cam.width_px - 1.0, cam.height_px - 1.0
    rays = cam.ray(np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]])) @ R_world_cam.T
    if np.any(rays[:, 2] >= 0.0):
        return np.full((4, 2), np.inf)
    return position_m[:2] + rays[:, :2] * (-position_m[2] / rays[:, 2])[:, None]


@dataclass
class DescentWorld:
    """A terrain with its texture and renderer, reusable for several descents (close it when done)."""

    terrain: Terrain
    texture_rgb: np.ndarray
    renderer: DescentRenderer
    seed: int
    spec: DescentTerrainSpec

    @staticmethod
    def build(
        seed: int, spec: DescentTerrainSpec | None = None, camera: DescentCameraConfig | None = None
    ) -> DescentWorld:
        spec = spec or DescentTerrainSpec()
        terrain = descent_terrain(spec, seed)
        texture = descent_texture(terrain, spec, seed)
        return DescentWorld(terrain, texture, DescentRenderer(terrain, texture, camera), seed, spec)

    def fly(self, conditions: DescentConditions) -> DescentRun:
        return simulate_descent(conditions, self.terrain, self.renderer, terrain_seed=self.seed)

    def close(self) -> None:
        self.renderer.close()

    def __enter__(self) -> DescentWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def with_wind(conditions: DescentConditions, wind_mps: np.ndarray) -> DescentConditions:
    """The same conditions with another wind (tests and sweeps)."""
    return replace(conditions, wind_mps=np.asarray(wind_mps, dtype=float))
