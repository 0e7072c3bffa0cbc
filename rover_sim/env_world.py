"""The Gymnasium environment's world: terrain, physics, renderer and camera calibration built for a world seed, as
:class:`rover_sim.world.world.World` builds them for a mission (same soil law, lenses, calibration draw and
rectification at the commanded mast pointing). A base class of :class:`rover_sim.env.RoverEnv`, whose settings it
reads."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from nav.rectify import Rectification
    from rover_sim.render.renderer import StereoRenderer
    from rover_sim.scenario.schema import Scenario
    from rover_sim.sim.physics import RoverSim
    from rover_sim.sim.sensors import SensorSuite
    from rover_sim.world.calibration import RunCalibration

MAX_TEXTURE_SIDE_PX = 8192  # as in Mission: ground texture memory stays under ~200 MB


class EnvWorld:
    """Builds and closes the environment's world (mixed into :class:`~rover_sim.env.RoverEnv`)."""

    scenario: Scenario
    cameras: tuple[str, ...]
    resolution_px: int
    shadows: bool
    image_noise: bool
    _sim: RoverSim | None
    _renderer: StereoRenderer | None
    _sensors: SensorSuite | None
    _calibration: RunCalibration | None
    _rectifications: dict[str, Rectification]
    _world_seed: int | None
    _world_sc: Scenario | None

    def _build_world(self, world_seed: int) -> None:
        from rover_sim.render.config import ImageNoise, RenderConfig
        from rover_sim.render.renderer import StereoRenderer, terrain_texture
        from rover_sim.sim.assembly import Sun
        from rover_sim.sim.physics import RoverSim
        from rover_sim.world.calibration import RunCalibration, build_true_lens
        from terrains import synthesize

        self._close_world()
        sc = self.scenario.model_copy(update={"seed": world_seed})
        if sc.terrain.streamed is not None:
            raise ValueError(f"scenario {sc.name!r}: the Gymnasium environment needs a whole-site terrain; "
                             "remove [terrain.streamed] (streamed sites run with `rover-sim run`)")  # fmt: skip
        terrain = synthesize(sc.terrain, world_seed)
        side = 2.0 * max(terrain.half_x_m, terrain.half_y_m)
        px_per_m = min(sc.appearance.texture_px_per_m, MAX_TEXTURE_SIDE_PX / side)
        ap = sc.appearance
        texture = terrain_texture(
            terrain, px_per_m, world_seed, fine_soil=ap.fine_soil, contrast=ap.contrast, patches=ap.patch_tuples()
        )
        self._sim = RoverSim(
            terrain,
            Sun(sc.sun.azimuth_deg, sc.sun.elevation_deg, self.shadows),
            texture_rgb=texture,
            timestep_s=sc.physics.timestep_s,
            soil_model=sc.physics.soil_model,
        )
        if sc.physics.deformable:
            self._sim.enable_deformation()
        noise = ImageNoise(seed=0) if self.image_noise else None  # its generator is re-seeded on every reset
        lens = sc.sensors.lens  # [sensors.lens] / [sensors.imaging]: the camera hardware, as World draws it
        self._calibration = RunCalibration(lens, world_seed) if lens.enabled else None
        config = RenderConfig(resolution_px=self.resolution_px, noise=noise, shadows=self.shadows,
                              imaging=sc.sensors.imaging, imaging_seed=world_seed)  # fmt: skip
        true_lens = None
        if self._calibration is not None:
            true_lens = build_true_lens(self._sim.model, self._sim.data, self._calibration, config.native_px)
        self._renderer = StereoRenderer(self._sim, config, lens=true_lens)
        self._world_seed, self._world_sc = world_seed, sc

    def _close_world(self) -> None:
        if self._sensors is not None:
            self._sensors.detach()
            self._sensors = None
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self._sim = None
        self._world_seed = self._world_sc = self._calibration = None
        self._rectifications = {}

    def _point_mast(self, sc: Scenario) -> None:
        """Command the scenario's mast pointing; the mast stops within its encoder error (flight), and the onboard
        rectification of each pair is computed from the calibrated models at the *commanded* pointing (as
        :meth:`rover_sim.world.world.World.calibrate` does; none in the ideal profile)."""
        from nav.rectify import rectification
        from rover_sim.world.calibration import MastEncoders, onboard_stereo_models

        sim, lens = self._sim, sc.sensors.lens
        pan_deg, elevation_deg = sc.nav.mast_pan_deg, sc.nav.mast_tilt_deg
        pan_true_deg, elevation_true_deg = MastEncoders(lens, sc.seed).true_angles_deg(pan_deg, elevation_deg)
        sim.set_mast(math.radians(pan_true_deg), -math.radians(elevation_true_deg))  # the tilt joint turns down
        self._rectifications = {}
        if self._calibration is None and not lens.has_mast_error:
            return
        for pair in self.cameras:
            _, calib = onboard_stereo_models(
                sim.model, sim.data, self._calibration, pair, self.resolution_px, pan_deg, elevation_deg
            )
            if calib is not None:
                self._rectifications[pair] = rectification(calib)
