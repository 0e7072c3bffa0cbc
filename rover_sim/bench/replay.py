"""Another visual odometer on the identical inputs of a run: a paired, open-loop comparison.

A :class:`ReplayedVO` rides along a closed-loop run as a listener on the mission's public hooks. It holds its own
onboard stack (dead reckoning and the other VO, built exactly as the scenario builds its own), receives every 8 Hz
observation and every VO pair the rover takes, runs its VO on the same pair, and keeps its own evaluator. Both
estimators then see the same images, IMU samples and encoder readings: their difference is the estimator's alone,
not a different route (the power of pairing on the same inputs). The rover still drives on the scenario's own VO:
a replayed VO does not steer, so its figures are open loop (a ``goto`` or autonav drive that the other VO would
have steered elsewhere is not replayed as such).

:func:`run_job_with_replays` is the sweep job that runs a scenario with replayed VOs (names from the job's
``params["replay"]``) and returns their metrics beside the run's own (``metrics["replays"][label]``).
"""

from __future__ import annotations

from pathlib import Path

from nav.trajectory import Pose
from rover_sim.apps.sweep import failed_result
from rover_sim.apps.sweep_jobs import Job, JobResult
from rover_sim.runtime import acceptance
from rover_sim.runtime.evaluator import Evaluator
from rover_sim.runtime.onboard import VoStep
from rover_sim.runtime.runner import Mission, onboard_for
from rover_sim.world.observation import Observation


class ReplayedVO:
    """A second onboard stack with another VO, fed the observations of ``mission`` (see the module doc)."""

    def __init__(self, mission: Mission, label: str, impl: str) -> None:
        sc = mission.sc
        spec = sc.nav.vo.model_copy(update={"impl": impl, "enabled": True})
        self.label, self.mission = label, mission
        self.onboard = onboard_for(sc, mission.world.start_pose(), spec, on_event=None)
        self.evaluator = Evaluator(sc.name, sc.seed, mission.evaluator.goal_xy, has_vo=True)
        self._pair: tuple[Observation, Pose] | None = None
        mission.tick_listeners.append(self.on_tick)
        mission.image_listeners.append(self.on_images)
        mission.vo_listeners.append(self.on_vo)
        mission.vo_reset_listeners.append(self.onboard.reset_vo)

    def _record(self, truth: Pose) -> None:
        ob = self.onboard
        self.evaluator.record(truth, ob.dead_reckoning.pose, ob.pose, ob.dead_reckoning.distance_m)

    def on_tick(self, obs: Observation, truth: Pose) -> None:
        self.onboard.observe(obs)
        self._record(truth)

    def on_images(self, obs: Observation, truth: Pose) -> None:
        self._pair = (obs, truth)  # the VO pair is the last one imaged before the run's own VO step reports

    def on_vo(self, step: VoStep, T_rover_cam) -> None:  # noqa: ANN001, ARG002
        if self._pair is None:
            return
        obs, truth = self._pair
        camera = self.mission.sc.nav.camera
        out = self.onboard.vo_step(obs, camera)
        res = out.result
        own = self.mission.vo_steps[-1] if self.mission.vo_steps else None
        self.evaluator.vo_step(
            truth, res.status, res.motion_rover, out.commanded_m, int(res.n_inliers), out.ms,
            reason=str(getattr(res, "reason", "")), no_texture=bool(own.no_texture) if own else False,
            covariance=getattr(res, "covariance", None), textured_frac=self.mission.evaluator.pair_textured_frac,
        )  # fmt: skip
        if res.status == "ok":
            self._record(truth)
        self._pair = None

    def metrics(self) -> dict:
        """metrics.json of the replayed VO, judged by the scenario's own criteria (the halt, if any, is the run's)."""
        m = self.mission
        halted = m.halted.kind if m.halted else None
        out = self.evaluator.metrics(wall_s=0.0, sim_s=m.sim.time_s, halted=halted, extra={}, timing={})
        out.passed, out.reason = acceptance.judge(out, m.sc.passing, error=m.error, keep_out=list(m.sc.keep_out),
                                                  keep_out_info=m.evaluator.keep_out_info)  # fmt: skip
        return out.deterministic_dict()


def run_job_with_replays(job: Job, jobs_dir: str) -> JobResult:
    """A sweep job (see :func:`rover_sim.apps.sweep.run_job`) with the VOs of ``job.params["replay"]``
    (label -> import path) replayed on the run's inputs; their metrics under ``metrics["replays"]``."""
    job_dir = Path(jobs_dir) / job.job_id
    replays: list[ReplayedVO] = []
    try:
        from rover_sim.runtime.run import run_scenario
        from rover_sim.scenario.schema import Scenario

        def attach(mission: Mission) -> None:
            if mission.onboard.vo is None:
                return  # a scenario without VO has nothing to replay
            replays.extend(ReplayedVO(mission, label, impl) for label, impl in job.params.get("replay", {}).items())

        metrics = run_scenario(Scenario.model_validate(job.scenario), job_dir, record=False, attach=attach)
        out = metrics.deterministic_dict() | {"replays": {r.label: r.metrics() for r in replays}}
        return JobResult(job.job_id, "ok", metrics=out)
    except Exception as e:  # noqa: BLE001 - isolation boundary, as run_job
        (job_dir / "metrics.json").unlink(missing_ok=True)
        return failed_result(job, e)
