"""The data of a Monte-Carlo sweep (:mod:`rover_sim.apps.sweep`): grid axes, jobs, their results and the sweep's.

Standard library only, as the sweep module: a spawned worker imports both before numpy loads."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class GridAxis:
    """One ``--grid dotted.key=v1,v2,...``: the raw TOML text of each value (as ``--set`` takes it) and its value."""

    key: str
    raw: tuple[str, ...]
    values: tuple[Any, ...]


@dataclass(frozen=True)
class Job:
    """One run of the sweep: a grid point and a seed, with the scenario resolved and validated."""

    job_id: str
    params: dict[str, Any]  # grid key -> value, in grid order
    seed: int
    scenario: dict[str, Any]  # Scenario.resolved_dict(); what the worker runs, and what job_id hashes

    @property
    def label(self) -> str:
        return " ".join([f"{k.rsplit('.', 1)[-1]}={v}" for k, v in self.params.items()] + [f"seed={self.seed}"])


@dataclass
class JobResult:
    job_id: str
    status: str  # "ok": the mission ran (whether or not it met its pass criterion); "failed": it raised or crashed
    metrics: dict[str, Any] | None = None  # metrics.json
    error: str | None = None  # one line, for results.csv
    traceback: str | None = None
    cached: bool = False  # read from an earlier run's metrics.json

    @property
    def ok(self) -> bool:
        return self.status == "ok"


@dataclass
class SweepResult:
    out_dir: Path
    axes: list[GridAxis]
    jobs: list[Job]
    results: list[JobResult]  # same order as jobs
    wall_s: float
    csv_path: Path
    plots: list[Path] = field(default_factory=list)

    @property
    def n_cached(self) -> int:
        return sum(r.cached for r in self.results)

    @property
    def n_failed(self) -> int:
        return sum(not r.ok for r in self.results)

    @property
    def n_run(self) -> int:
        return len(self.results) - self.n_cached
