"""Scenarios over seeds: the runs behind ``bench suite`` and ``bench vo``, and what is read from each.

Every (case, profile, seed) is one job of the sweep engine (:func:`rover_sim.apps.sweep.run_jobs`): local spawn
workers (``--workers``) or a Dask scheduler (``--scheduler``), each job its own closed-loop run, so the results are
the same whatever the worker count. A case is a scenario (catalogue name, TOML path or a :class:`Scenario`) with
its own ``--set`` overrides; the profile and the perturbation are overrides too, so they are part of a job's id.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from rover_sim.apps.sweep import job_id_of, run_job, run_jobs
from rover_sim.apps.sweep_jobs import Job, JobResult
from rover_sim.bench import stats
from rover_sim.runtime import acceptance
from rover_sim.scenario.loading import load_scenario, scenario_from_dict
from rover_sim.scenario.schema import Scenario


@dataclass(frozen=True)
class Metric:
    """A figure read from a run's ``metrics.json``: how to read it, which way is better, how to print it."""

    key: str
    label: str
    read: Callable[[dict], float | None]
    higher_is_better: bool = False


def _get(key: str) -> Callable[[dict], float | None]:
    return lambda m: m.get(key)


def _segment(estimator: str, length: str) -> Callable[[dict], float | None]:
    return lambda m: ((m.get("kitti_segment_error_pct") or {}).get(estimator) or {}).get(length)


def _nees(which: str) -> Callable[[dict], float | None]:
    def read(m: dict) -> float | None:
        n = (m.get("extra") or {}).get("vo_covariance_nees")
        if not n:
            return None
        return n.get("step_median") if which == "step_median" else (n.get("segment_median") or {}).get(which)

    return read


METRICS: dict[str, Metric] = {
    m.key: m
    for m in (
        Metric("distance_m", "distance (m)", _get("distance_m")),
        Metric("max_slip_pct", "max slip (%)", _get("max_slip_pct")),
        Metric("dr_error_pct", "DR error (%)", _get("dr_error_pct")),
        Metric("vo_error_pct", "VO error (%)", _get("vo_error_pct")),
        Metric("vo_segment_1m_pct", "VO 1 m segments (%)", _segment("vo", "1m")),
        Metric("vo_segment_5m_pct", "VO 5 m segments (%)", _segment("vo", "5m")),
        Metric("vo_convergence_pct", "VO convergence (%)", _get("vo_convergence_pct"), higher_is_better=True),
        Metric("vo_rotation_error_deg_per_m", "VO rotation error (deg/m)", _get("vo_rotation_error_deg_per_m")),
        Metric("false_positives", "VO false positives", _get("false_positives")),
        Metric("goal_distance_m", "goal distance (m)", _get("goal_distance_m")),
        Metric("vo_nees_step", "VO NEES per step", _nees("step_median")),
        Metric("vo_nees_5m", "VO NEES over 5 m", _nees("5m")),
    )
}


@dataclass(frozen=True)
class Case:
    """One row of a benchmark table: a scenario and the overrides that make this row of it."""

    name: str
    scenario: str | Path | Scenario
    overrides: tuple[str, ...] = ()

    def load(self, seed: int, overrides: list[str]) -> Scenario:
        sets = list(self.overrides) + overrides
        if isinstance(self.scenario, Scenario):
            return scenario_from_dict(self.scenario.resolved_dict(), f"<{self.scenario.name}>", sets + [f"seed={seed}"])
        return load_scenario(self.scenario, sets, seed)


def profile_overrides(profile: str) -> list[str]:
    """``--set`` overrides that select a sensor profile."""
    return [f'sensors.profile="{profile}"']


def perturb_overrides(perturb: tuple[float, int] | None) -> list[str]:
    """``--perturb EPS:SEED`` as ``--set`` overrides (none when not perturbed)."""
    if perturb is None:
        return []
    return [f"physics.perturb_size={perturb[0]!r}", f"physics.perturb_seed={perturb[1]}"]


def parse_perturb(text: str | None) -> tuple[float, int] | None:
    """``EPS[:SEED]`` -> (EPS, SEED); SEED defaults to 0. A bad value is a one-line ConfigError naming the option."""
    from rover_sim.errors import ConfigError

    if text is None:
        return None
    eps_text, _, seed_text = text.partition(":")
    try:
        eps, seed = float(eps_text), int(seed_text or 0)
    except ValueError:
        raise ConfigError("--perturb", text, "expected EPS[:SEED], e.g. 1e-6 or 1e-6:3") from None
    if not 0.0 < eps <= 0.01 or seed < 0:
        raise ConfigError("--perturb", text, "EPS must be in (0, 0.01] (metres and radians), SEED >= 0")
    return eps, seed


@dataclass
class SeedRuns:
    """One case on one profile over its seeds: each seed's metrics.json (None where the job failed) and error."""

    case: Case
    profile: str
    scenario: Scenario  # as resolved at the first seed (its [pass] criteria judge every seed)
    metrics: dict[int, dict | None] = field(default_factory=dict)
    errors: dict[int, str] = field(default_factory=dict)
    interrupt: KeyboardInterrupt | None = None  # Ctrl-C / SIGTERM stopped the runs (re-raise once reported)
    replays: dict[str, SeedRuns] = field(default_factory=dict)  # label -> a VO replayed on these runs' inputs

    def values(self, key: str) -> dict[int, float | None]:
        m = METRICS[key]
        return {s: (m.read(r) if r is not None else None) for s, r in self.metrics.items()}

    def run_verdicts(self) -> dict[int, tuple[bool, str]]:
        out = {}
        for s, r in self.metrics.items():
            if r is None:
                out[s] = (False, f"run did not complete: {self.errors.get(s, 'unknown error')}")
            else:
                out[s] = (bool(r["passed"]), str(r["reason"]))
        return out

    def summaries(self) -> dict[str, stats.Summary]:
        return {k: stats.summarize(self.values(k), METRICS[k].higher_is_better) for k in METRICS}

    def verdict(self) -> acceptance.DistributionVerdict:
        values = {k: [v for v in self.values(k).values() if v is not None] for k in METRICS}
        return acceptance.judge_distribution(self.run_verdicts(), values, self.scenario.passing.distribution,
                                             stats.percentile)  # fmt: skip

    @property
    def interrupted(self) -> bool:
        return any(e == "interrupted" for e in self.errors.values())


def run_seeded(
    cases: list[Case],
    seeds: tuple[int, ...],
    profiles: tuple[str, ...],
    out_root: Path,
    *,
    overrides: list[str] | None = None,
    perturb: tuple[float, int] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    on_result: Callable[[int, int, str], None] | None = None,
    replay: dict[str, str] | None = None,
) -> list[SeedRuns]:
    """Run every case x profile x seed; one :class:`SeedRuns` per case and profile, in (profile, case) order.
    Jobs already completed under ``out_root/jobs`` are not reused: each benchmark run measures this build.
    Ctrl-C / SIGTERM: the jobs that did not finish are reported as ``"interrupted"`` and every group carries the
    interrupt in :attr:`SeedRuns.interrupt` for the caller to re-raise once it has reported. ``replay``: label ->
    VO import path, each run on the identical inputs of every run (:mod:`rover_sim.bench.replay`); their figures
    in each group's :attr:`SeedRuns.replays`."""
    extra = list(overrides or []) + perturb_overrides(perturb)
    planned: list[tuple[SeedRuns, int, Job]] = []
    groups: list[SeedRuns] = []
    for profile in profiles:
        for case in cases:
            sets = extra + profile_overrides(profile)
            first = case.load(seeds[0], sets)
            group = SeedRuns(case, profile, first)
            group.replays = {label: SeedRuns(case, profile, first) for label in replay or {}}
            groups.append(group)
            for seed in seeds:
                sc = first if seed == seeds[0] else case.load(seed, sets)
                resolved = sc.resolved_dict()
                params = {"case": case.name, "profile": profile} | ({"replay": dict(replay)} if replay else {})
                planned.append((group, seed, Job(job_id_of(resolved), params, seed, resolved)))
    jobs_dir = out_root / "jobs"
    shutil.rmtree(jobs_dir, ignore_errors=True)
    by_id: dict[str, list[tuple[SeedRuns, int]]] = {}
    for group, seed, job in planned:  # identical resolved scenarios are one job that fills every row naming it
        by_id.setdefault(job.job_id, []).append((group, seed))

    def note(done: int, total: int, job: Job, result: JobResult) -> None:
        for group, seed in by_id[job.job_id]:
            store(group, seed, result)
        if on_result is not None:
            group, seed = by_id[job.job_id][0]
            on_result(done, total, f"{group.profile}: {group.case.name} seed {seed}")

    unique = list({job.job_id: job for _, _, job in planned}.values())
    try:
        job_fn = run_job
        if replay:
            from rover_sim.bench.replay import run_job_with_replays as job_fn
        run_jobs(unique, jobs_dir, workers=workers, scheduler=scheduler, on_result=note, reuse=False, job_fn=job_fn)
    except KeyboardInterrupt as e:  # report what ran; the caller re-raises (exit 130 / 143)
        for group, seed, _ in planned:
            for g in (group, *group.replays.values()):
                g.interrupt = e
                if seed not in g.metrics:
                    g.metrics[seed], g.errors[seed] = None, "interrupted"
    return groups


def store(group: SeedRuns, seed: int, result: JobResult) -> None:
    if result.ok and result.metrics is not None:
        group.metrics[seed] = result.metrics
        for label, sub in group.replays.items():
            m = (result.metrics.get("replays") or {}).get(label)
            sub.metrics[seed] = m
            if m is None:
                sub.errors[seed] = "not replayed (the scenario runs no VO)"
    else:
        group.metrics[seed], group.errors[seed] = None, result.error or "failed"
        for sub in group.replays.values():
            sub.metrics[seed], sub.errors[seed] = None, result.error or "failed"


def cell(s: stats.Summary, digits: int = 2) -> str:
    """``median [lo, hi]`` of a summary, ``-`` when not measured."""
    if s.median is None:
        return "-"
    lo, hi = s.ci90 or (s.median, s.median)
    return f"{s.median:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"
