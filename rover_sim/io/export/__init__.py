"""Dataset export: a run's stereo pairs, IMU, wheel encoders, ground truth and onboard estimates as a KITTI, EuRoC
or ROS 2 (MCAP) dataset, for running external VO/VIO/SLAM on simulated Mars drives.

A :class:`DatasetSink` subscribes to a :class:`~rover_sim.runtime.runner.Mission`'s public hooks and hands
each stream to one or more :class:`~rover_sim.io.export.base.DatasetWriter` s as it arrives (images go to disk at
once, nothing accumulates in memory); :func:`export_scenario` runs a scenario with a sink attached::

    from rover_sim.io.export import export_scenario
    summary = export_scenario("wopmay", "runs/wopmay_kitti", formats=("kitti",), overrides=["commands.0.distance_m=2"])

Which pairs become frames:

* ``rate_hz=None`` (``--at-vo-steps``): the pairs of ``camera`` the rover itself takes (VO steps, autonav hazcam
  looks), exactly as the onboard stack received them, read-noise included. The run is untouched.
* ``rate_hz=R`` (``--rate-hz``): an extra pair of ``camera`` rendered from the 8 Hz tick whenever R Hz is due.
  These renders skip the image read-noise (a 0.19 grey-level rms 12-bit dither) so that they draw nothing from the
  run's image-noise generator: the run (VO, the path, every estimate) stays bit-identical to a plain ``rover-sim
  run`` of the same scenario, at the cost of noise-free extra frames.

Every stream's timestamps are strictly increasing (:class:`~rover_sim.io.export.base.Stream`): of equal stamps the
first image and the last pose are kept. Ground truth comes from the same ticks the run's evaluator records, so it
equals the run's ``trajectories/truth.tum`` (written beside the dataset in ``OUT/run/``).

Images are always the rectified pairs the onboard stack uses (the flight profile's raw renders are rectified with
the calibration the onboard stack holds at that moment), and the camera poses written with them (KITTI ``Tr`` and
``poses/``, EuRoC ``T_BS``, the bag's ``/tf_static``, the Kalibr files) are the true poses of those rectified
cameras (:mod:`rover_sim.io.export.camera_truth`), not of the physical cameras.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from nav.rectify import rectification
from nav.trajectory import Pose
from nav.types import ImuSample
from rover_sim import interrupts
from rover_sim.errors import RoverSimError
from rover_sim.io.export.base import DatasetWriter, ExportMeta, Frame, Stream
from rover_sim.io.export.camera_truth import true_rectified_pose

if TYPE_CHECKING:
    from rover_sim.render.renderer import StereoFrame, StereoRenderer
    from rover_sim.runtime.runner import Mission
    from rover_sim.scenario.schema import Scenario
    from rover_sim.world.observation import Observation

__all__ = ["CAMERAS", "FORMATS", "DatasetSink", "DatasetWriter", "ExportOptionError", "ExportSummary", "Frame",
           "check_options", "export_scenario", "make_writer"]  # fmt: skip

FORMATS: tuple[str, ...] = ("kitti", "euroc", "rosbag2")
CAMERAS: tuple[str, ...] = ("navcam", "hazcam_front", "hazcam_rear")
MAX_RATE_HZ = 8.0  # the tick rate: frames can be rendered no faster


class ExportOptionError(RoverSimError, ValueError):
    """A bad export option; the message names the option and the allowed values."""


def check_options(
    fmt: str, camera: str, rate_hz: float | None, at_vo_steps: bool = False, openvins: bool = False
) -> None:
    if fmt not in FORMATS:
        raise ExportOptionError(f"--format {fmt!r}: choose one of {', '.join(FORMATS)}")
    if camera not in CAMERAS:
        raise ExportOptionError(f"--camera {camera!r}: choose one of {', '.join(CAMERAS)}")
    if rate_hz is not None and at_vo_steps:
        raise ExportOptionError("--rate-hz and --at-vo-steps exclude each other: give one of them (or neither)")
    if rate_hz is not None and not (0.0 < rate_hz <= MAX_RATE_HZ):
        raise ExportOptionError(f"--rate-hz {rate_hz:g}: must be > 0 and <= {MAX_RATE_HZ:g} (the tick rate)")
    if openvins and fmt != "euroc":
        raise ExportOptionError(f"--openvins writes OpenVINS's files beside a EuRoC export: --format euroc, not {fmt}")


def make_writer(fmt: str, out: Path, openvins: bool = False) -> DatasetWriter:
    """The writer of ``fmt`` rooted at ``out`` (KITTI: ``out/sequences``, EuRoC: ``out/mav0`` and the Kalibr files
    beside it, with ``openvins`` OpenVINS's too; ROS 2: ``out/rosbag2``)."""
    check_options(fmt, CAMERAS[0], None)
    out = Path(out)
    if fmt == "kitti":
        from rover_sim.io.export.kitti import KittiWriter

        return KittiWriter(out)
    if fmt == "euroc":
        from rover_sim.io.export.euroc import EurocWriter

        return EurocWriter(out, openvins=openvins)
    from rover_sim.io.export.rosbag2 import Rosbag2Writer

    return Rosbag2Writer(out / "rosbag2")


def render_without_noise(renderer: StereoRenderer, camera: str) -> StereoFrame:
    """A pair rendered without drawing from the run's noise generator: the ideal profile's read noise is off; the
    flight profile's CCD noise is drawn from a copy of the stream, restored afterwards."""
    config = renderer.config
    if renderer.imaging is not None:
        with renderer.imaging.replayed_noise():
            return renderer.render_pair(camera)
    if config.noise is None:
        return renderer.render_pair(camera)
    renderer.config = dataclasses.replace(config, noise=None)
    try:
        return renderer.render_pair(camera)
    finally:
        renderer.config = config


@dataclass(frozen=True)
class ExportSummary:
    format: str
    frames: int
    imu_samples: int
    duration_s: float
    out: str
    dropped_duplicates: int = 0  # samples dropped because their timestamp repeated an earlier one
    reason: str = ""  # the run's metrics.reason: "run did not complete: interrupted (SIGTERM)" for a cut-short one

    def to_json(self) -> dict:
        return {"format": self.format, "frames": self.frames, "imu_samples": self.imu_samples,
                "duration_s": self.duration_s, "out": self.out, "reason": self.reason}  # fmt: skip


class DatasetSink:
    """Subscribes to a Mission's hooks; forwards frames, IMU, encoders, truth and estimates to ``writers``."""

    def __init__(self, writers: Sequence[DatasetWriter], camera: str = "navcam", rate_hz: float | None = None) -> None:
        check_options(FORMATS[0], camera, rate_hz)
        self.writers = list(writers)
        self.camera, self.rate_hz = camera, rate_hz
        self.mission: Mission | None = None
        self.next_due_s: float | None = None
        self.frames: Stream[Frame] = Stream(self.each("frame", whole=True))
        self.imu: Stream[ImuSample] = Stream(self.each("imu"))
        self.enc: Stream[tuple] = Stream(lambda item: [w.encoders(*item) for w in self.writers])
        self.gt: Stream[Pose] = Stream(self.each("truth"), keep="last")
        self.dr: Stream[Pose] = Stream(lambda p: [w.estimate("dead_reckoning", p) for w in self.writers], keep="last")
        self.vo: Stream[Pose] = Stream(lambda p: [w.estimate("vo", p) for w in self.writers], keep="last")

    def each(self, method: str, whole: bool = False):  # noqa: ANN201
        """Hand an item to every writer's ``method``. ``whole``: Ctrl-C or SIGTERM is held until every writer has
        written it (a frame is several files and index lines: an interrupted export keeps whole frames only)."""

        def emit(item: object) -> None:
            if not whole:
                for w in self.writers:
                    getattr(w, method)(item)
                return
            with interrupts.deferred() as pending:
                for w in self.writers:
                    getattr(w, method)(item)
            if pending.exc is not None:
                raise pending.exc

        return emit

    @property
    def mode(self) -> str:
        return "vo-steps" if self.rate_hz is None else f"rate {self.rate_hz:g} Hz"

    def attach(self, mission: Mission) -> DatasetSink:
        self.mission = mission
        sensors = mission.world.sensors
        imu = sensors.imu.params
        meta = ExportMeta(
            scenario=mission.sc.name, seed=mission.sc.seed, camera=self.camera, mode=self.mode,
            imu_rate_hz=1.0 / sensors.imu_period_s, gyro_noise_density=imu.gyro_white_rad_sqrt_s,
            accel_noise_density=imu.accel_white_m_s2_sqrt_hz, gyro_bias_sigma=imu.gyro_bias_rad_s,
            gyro_bias_corr_time_s=imu.gyro_bias_corr_time_s, encoder_rate_hz=sensors.encoders.params.rate_hz,
            has_vo=mission.onboard.vo is not None,
        )  # fmt: skip
        for w in self.writers:
            w.start(meta)
        mission.tick_listeners.append(self.on_tick)
        mission.vo_listeners.append(self.on_vo)
        if self.rate_hz is None:
            mission.image_listeners.append(self.on_images)
        return self

    # ------------------------------------------------------------------ listeners
    def on_tick(self, obs: Observation, truth: Pose) -> None:
        mission = self.mission
        assert mission is not None, "attach() the sink first"
        for s in obs.imu:
            self.imu.push(s.t_s, s)
        pan, elevation = map(math.radians, (obs.mast_pan_deg, obs.mast_elevation_deg))
        for e in obs.encoders:
            self.enc.push(e.t_s, (e, pan, elevation))
        self.gt.push(truth.t_s, truth)
        # the estimates keep their own stamps (their last encoder update), so a tick without a new encoder reading
        # repeats a stamp: the last pose per stamp is kept (the one after a VO correction, if any)
        ob = mission.onboard
        self.dr.push(ob.dead_reckoning.pose.t_s, ob.dead_reckoning.pose)
        if ob.vo is not None:
            self.vo.push(ob.pose.t_s, ob.pose)
        if self.rate_hz is not None and (self.next_due_s is None or obs.t_s >= self.next_due_s - 1e-9):
            period = 1.0 / self.rate_hz
            self.next_due_s = obs.t_s if self.next_due_s is None else self.next_due_s
            while self.next_due_s <= obs.t_s + 1e-9:
                self.next_due_s += period
            f = render_without_noise(mission.world.renderer, self.camera)
            self.push_frame(mission.world.observation_with([], [], {self.camera: f}), truth, rectify=True)

    def on_vo(self, _step: object, _T_rover_cam: object) -> None:
        """After a VO step: the corrected onboard pose replaces the one of the same stamp."""
        if self.mission is not None and self.mission.onboard.vo is not None:
            pose = self.mission.onboard.pose
            self.vo.push(pose.t_s, pose)

    def on_images(self, obs: Observation, truth: Pose) -> None:
        if self.camera in obs.images and self.mission is not None:
            self.push_frame(obs, truth, rectify=False)

    def push_frame(self, obs: Observation, truth: Pose, rectify: bool) -> None:
        """The pair of ``obs`` as the onboard stack rectifies it, with the true poses of the rectified cameras.

        ``rectify`` False: a pair the rover takes, rectified by the onboard stack itself (as its stereo and VO
        use it). True: an extra render, rectified here with the calibration the onboard stack holds now, without
        showing it to the onboard stack (its epipolar check must not see pairs the rover never took)."""
        mission = self.mission
        assert mission is not None, "attach() the sink first"
        onboard, camera = mission.onboard, self.camera
        if rectify:
            raw, calib = obs.pair(camera), onboard.rectifying_calibration(obs, camera)
            rect = None if calib is None else rectification(calib)
            left, right = (raw.left_u8, raw.right_u8) if rect is None else rect.apply(raw.left_u8, raw.right_u8)
            rig = raw.rig if rect is None else rect.rig
        else:
            pair = onboard.rectified(obs, camera)  # flight profile: raw pairs exported rectified
            left, right, rig = pair.left_u8, pair.right_u8, pair.rig
            calib = onboard.rectifying_calibration(obs, camera)  # what that pair was rectified with
        true_rig = mission.world.renderer.rig(camera)  # the mast as it physically stands
        T_left, T_right = true_rig.left.T_rover_cam, true_rig.right.T_rover_cam
        truth_lens = mission.world.calibration
        if calib is not None and truth_lens is not None:  # rectified through calibrated models: the rectified cameras
            T_left = true_rectified_pose(rig.left, calib.left, truth_lens.true_model(true_rig.left))
            T_right = true_rectified_pose(rig.right, calib.right, truth_lens.true_model(true_rig.right))
        t_s = obs.pair(camera).t_s
        self.frames.push(t_s, Frame(t_s, camera, left, right, rig, T_left, T_right, true_rig.left.T_rover_cam, truth))

    def close(self, fmt: str = "", out: str = "") -> ExportSummary:
        """Flush the held-back poses and close every writer."""
        for s in (self.gt, self.dr, self.vo):
            s.flush()
        for w in self.writers:
            w.close()
        first, last = self.gt.first_t, self.gt.last_t
        dropped = sum(s.dropped for s in (self.frames, self.imu, self.enc, self.gt))
        duration = 0.0 if first is None or last is None else round(last - first, 6)
        fmt = fmt or ",".join(w.name for w in self.writers)
        return ExportSummary(fmt, self.frames.count, self.imu.count, duration, out, dropped)


def export_scenario(
    scenario: str | Path | Scenario,
    out: str | Path,
    formats: Sequence[str] = ("kitti",),
    camera: str = "navcam",
    rate_hz: float | None = None,
    seed: int | None = None,
    overrides: list[str] | None = None,
    progress: bool = False,
    openvins: bool = False,
) -> ExportSummary:
    """Run ``scenario`` with a :class:`DatasetSink` writing ``formats`` into ``out`` (which must be empty or new);
    the run's own outputs (metrics, ``trajectories/*.tum``, plots) go to ``out/run/``; ``openvins``: OpenVINS's
    calibration files beside a EuRoC export's Kalibr files. Nothing is written if the
    mission cannot start (e.g. a plugin does not load). ``summary.reason`` is the run's ``metrics.reason``: an
    interrupted run (Ctrl-C, SIGTERM) leaves the dataset written up to the interrupt and says so there."""
    from rover_sim.io.progress import SimProgress
    from rover_sim.runtime.run import write_outputs
    from rover_sim.runtime.runner import Mission
    from rover_sim.scenario.loading import load_scenario
    from rover_sim.scenario.schema import Scenario

    for fmt in formats:
        check_options(fmt, camera, rate_hz)
    if openvins and "euroc" not in formats:
        raise ExportOptionError("--openvins writes OpenVINS's files beside a EuRoC export: include the euroc format")
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides, seed)
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ExportOptionError(f"--out {out}: exists and is not an empty directory; give a new one")
    bar = SimProgress(f"export {sc.name}") if progress else None  # a bar on a terminal, plain lines in a log

    def on_progress(t_s: float, _msg: str) -> None:
        if bar is not None:
            bar.update(t_s)

    try:
        mission = Mission(sc, progress=on_progress)
        try:
            out.mkdir(parents=True, exist_ok=True)
            writers = [make_writer(f, out, openvins and f == "euroc") for f in formats]
            sink = DatasetSink(writers, camera, rate_hz).attach(mission)
            try:
                metrics = mission.run()
            finally:
                summary = sink.close(",".join(formats), str(out))
        finally:
            mission.close()
    finally:
        if bar is not None:
            bar.close()
    write_outputs(mission, metrics, out / "run")
    return dataclasses.replace(summary, reason=metrics.reason)
