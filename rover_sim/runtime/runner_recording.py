"""What the runner records beyond its events and poses: the terrain (static, streamed tiles or a deformable run's
ground tiles), keep-out zones, the trajectories and scalars every few ticks, and each VO pair's images, stereo points
and feature tracks. A base class of :class:`rover_sim.runtime.runner.Mission`, whose state it reads."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from nav.geometry import R_to_rpy
from rover_sim.io.rut_log import RutLog

if TYPE_CHECKING:
    from rover_sim.io.recorder_protocol import Recorder
    from rover_sim.runtime.evaluator import Evaluator
    from rover_sim.runtime.onboard import Onboard
    from rover_sim.scenario.schema import Scenario
    from rover_sim.world.world import World


class RunRecording:
    """The runner's recording calls (mixed into :class:`~rover_sim.runtime.runner.Mission`; they also read its
    ``sim`` and ``terrain`` views)."""

    sc: Scenario
    rec: Recorder
    world: World
    onboard: Onboard
    evaluator: Evaluator
    rut_log: RutLog | None
    step: int

    def log_terrain_tiles(self) -> None:
        """A streamed site: log the tiles of the current window not logged before (each tile once)."""
        self._terrain_version = self.sim.terrain_version
        if self.sim.streamer is not None:
            for key, tile_terrain in self.sim.streamer.new_tiles(self.terrain):
                self.rec.log_terrain_tile(key, tile_terrain)

    def log_static(self) -> None:
        if self.sim.streamer is not None:
            self.log_terrain_tiles()
        elif self.sim.deform is not None:  # the ground as tiles re-logged where ruts change them (io/rut_log.py)
            self.rec.log_terrain(self.terrain, ground=False)
            self.rut_log = RutLog(self.sim, self.rec)
            self.rut_log.log_all(self.sim.time_s, self.step)
        else:
            self.rec.log_terrain(self.terrain)
        for z in self.sc.keep_out:
            self.rec.log_keep_out(z.name, z.x_m, z.y_m, z.radius_m, float(self.terrain.height_at(z.x_m, z.y_m)))
        self.rec.log_camera(self.sc.nav.camera, self.world.onboard_rig(self.sc.nav.camera), self.sim.time_s)

    def log_tracks(self, t: float) -> None:
        ev = self.evaluator
        for name, poses in (("truth", ev.truth), ("dead_reckoning", ev.dr_poses)):
            self.rec.log_trajectory(name, t, self.step, poses.positions_xyz_m)
        if self.onboard.vo is not None:
            self.rec.log_trajectory("vo", t, self.step, ev.onboard_poses.positions_xyz_m)
        truth = ev.truth[-1]
        rpy = R_to_rpy(truth.R_world_rover)
        gt = self.sim.ground_truth()
        errors = {
            "position_error_m/dead_reckoning": float(
                np.linalg.norm(ev.dr_poses[-1].position_xyz_m - truth.position_xyz_m)
            )
        }
        if self.onboard.vo is not None:
            errors["position_error_m/vo"] = float(
                np.linalg.norm(ev.onboard_poses[-1].position_xyz_m - truth.position_xyz_m)
            )
        slip = float(np.nanmean(gt.wheel_slip)) if np.isfinite(gt.wheel_slip).any() else math.nan
        self.rec.log_scalars(
            t,
            self.step,
            {
                "tilt_deg": gt.tilt_deg,
                "roll_deg": math.degrees(rpy[0]),
                "pitch_deg": math.degrees(rpy[1]),
                **errors,
                "wheel_slip_pct": 100.0 * slip,
                "sinkage_mean_m": float(np.mean(gt.wheel_sinkage_m)),
            },
        )

    def log_frame(self, obs, camera: str, res) -> None:  # noqa: ANN001
        pair = self.onboard.rectified(obs, camera)
        t = self.sim.time_s
        self.rec.log_camera(camera, pair.rig, t)
        disparity = None
        if self.rec.wants_images():
            # dense stereo of the VO pair, for the recording only (placed with the onboard pose)
            ri = self.onboard.range_image(obs, camera)
            disparity = ri.disparity_px
            from nav.camera import transform_points

            pts = transform_points(self.onboard.pose.as_matrix(), ri.points_rover_m())
            near = np.linalg.norm(pts[:, :2] - pts[:, :2].mean(0), axis=1) < 15
            self.rec.log_points(camera, t, self.step, pts[near])
        self.rec.log_stereo_images(camera, t, self.step, pair.left_u8, pair.right_u8, disparity)
        tracks = getattr(res, "tracks", None)
        if tracks is not None and len(tracks):
            inliers = getattr(res, "inliers", None)
            inl = inliers if inliers is not None else np.ones(len(tracks), bool)
            self.rec.log_vo_features(camera, t, self.step, tracks.uv_prev_left, tracks.uv_cur_left, inl)
