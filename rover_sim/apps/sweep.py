"""Monte-Carlo sweeps: one scenario over a grid of ``--set`` values times seeds, run in parallel, gathered into a table.

The steps of :func:`run_sweep`:

1. plan: the cartesian product of the grid axes times the seeds; each point is loaded and validated here (a bad
   value fails before anything runs) and becomes a :class:`Job` holding its fully resolved scenario;
2. skip: a job whose ``DIR/jobs/<job_id>/metrics.json`` is already complete is not run again (``job_id`` is a hash
   of the resolved scenario, so an edited scenario file or a changed default gives new jobs);
3. run: the rest go to an executor: this process (``workers=0``), a local ``spawn`` process pool (the default;
   never ``fork``: this process may already hold an EGL context, which a fork would copy), or a Dask cluster
   (``scheduler="tcp://host:port"``, the ``rover-sim[dask]`` extra, tasks submitted with ``retries=2``). Each job is
   ``run_scenario(..., record=False)`` into its own ``DIR/jobs/<job_id>/``; an exception in one job is caught in
   its worker and reported as that job's failure, and a crashed local worker fails the jobs it took down (re-run the
   sweep to retry them: completed jobs are skipped). Workers get the resolved scenario, not the file; on a remote
   cluster they write each job's outputs at the same path on their own disks, while ``metrics.json`` (from the
   returned result), ``results.csv`` and the plots are written here;
4. gather: ``DIR/results.csv`` (one row per job, in grid order) and ``DIR/plots/*.png``.

This module imports only the standard library at the top: a spawned worker imports it to start, and must be able to
set its thread limits before numpy loads.
"""

from __future__ import annotations

import csv
import hashlib
import itertools
import json
import os
import time
import traceback
import uuid
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

from rover_sim.apps.sweep_jobs import GridAxis, Job, JobResult, SweepResult
from rover_sim.apps.sweep_plots import plot_sweep
from rover_sim.errors import ConfigError, DaskUnavailable, SchedulerUnreachable

#: metrics.json keys copied into results.csv (the core metric set), in column order
METRIC_COLUMNS = (
    "scenario",
    "seed",
    "distance_m",
    "dr_error_pct",
    "vo_error_pct",
    "vo_convergence_pct",
    "max_slip_pct",
    "mean_slip_pct",
    "passed",
    "reason",
    "wall_s",
)
JOB_ID_CHARS = 16  # hex digits of sha256 kept: collisions are negligible for any sweep that fits on a disk
DASK_RETRIES = 2  # Dask re-runs a task this often when its worker dies or it raises
DASK_CONNECT_TIMEOUT_S = 30.0
# Same thread limits as Dask's nanny (distributed.nanny.pre-spawn-environ), so both backends compute alike and
# K workers on K cores do not oversubscribe them.
WORKER_THREAD_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


JobFn = Callable[[Job, str], JobResult]
OnResult = Callable[[int, int, Job, JobResult], None]


def _no_progress(done: int, total: int, job: Job, result: JobResult) -> None:
    """The do-nothing progress callback."""


# ------------------------------------------------------------------------------------------------- planning


def _split_top_level(text: str) -> list[str]:
    """Split on commas outside brackets and quotes: ``10,[1,2],"a,b"`` -> ``['10', '[1,2]', '"a,b"']``."""
    items, depth, quote, start = [], 0, "", 0
    for i, ch in enumerate(text):
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            items.append(text[start:i])
            start = i + 1
    items.append(text[start:])
    return [s.strip() for s in items]


def parse_grid(text: str) -> GridAxis:
    """``terrain.slope.slope_deg=10,15,20`` -> a :class:`GridAxis`; values are TOML like ``--set`` values."""
    from rover_sim.scenario.loading import parse_override

    if "=" not in text:
        raise ConfigError("--grid", text, "expected dotted.key=v1,v2,... (e.g. terrain.slope.slope_deg=10,15,20)")
    key, raw_values = (s.strip() for s in text.split("=", 1))
    if key == "seed":
        raise ConfigError("--grid", key, "use --seeds N to sweep seeds 0..N-1")
    raw = _split_top_level(raw_values)
    if not key or any(not r for r in raw):
        raise ConfigError("--grid", text, "empty key or value; expected dotted.key=v1,v2,...")
    if len(set(raw)) != len(raw):
        raise ConfigError("--grid", key, f"repeated value in {raw_values!r}")
    return GridAxis(key, tuple(raw), tuple(parse_override(f"{key}={r}")[1] for r in raw))


def job_id_of(resolved: dict[str, Any]) -> str:
    """Stable id of a job: sha256 of its resolved scenario as canonical JSON."""
    blob = json.dumps(resolved, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:JOB_ID_CHARS]


def plan_jobs(
    scenario: str | Path,
    axes: Sequence[GridAxis],
    seeds: int | Iterable[int],
    overrides: Sequence[str] = (),
) -> list[Job]:
    """The cartesian product of the axes (first axis varies slowest) times the seeds, each loaded and validated.

    ``overrides`` (``--set`` texts) apply to every job before the grid values. Points that resolve to the same
    scenario (``10`` and ``10.0``) are one job.
    """
    from rover_sim.scenario.loading import load_scenario

    keys = [a.key for a in axes]
    if len(set(keys)) != len(keys):
        raise ConfigError("--grid", ", ".join(keys), "a key appears in two --grid options; give it once")
    seed_list = list(range(seeds)) if isinstance(seeds, int) else list(seeds)
    if not seed_list:
        raise ConfigError("--seeds", str(seeds), "need at least one seed")
    jobs: dict[str, Job] = {}
    points = itertools.product(*[list(zip(a.raw, a.values, strict=True)) for a in axes])
    for point, seed in itertools.product(list(points), seed_list):
        grid = [f"{k}={raw}" for k, (raw, _) in zip(keys, point, strict=True)]
        flags = [f"--set {o}" for o in overrides] + [f"--grid {g}" for g in grid]
        resolved = load_scenario(scenario, list(overrides) + grid, seed, flags).resolved_dict()
        job = Job(job_id_of(resolved), {k: v for k, (_, v) in zip(keys, point, strict=True)}, seed, resolved)
        jobs.setdefault(job.job_id, job)
    return list(jobs.values())


# ------------------------------------------------------------------------------------------------- one job


def _write_json(path: Path, obj: Any) -> None:
    """Write atomically (a crash never leaves half a file that looks complete)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:6]}.tmp")
    tmp.write_text(json.dumps(obj, indent=2, default=str))
    os.replace(tmp, path)


def load_completed(job_dir: Path) -> dict[str, Any] | None:
    """The metrics of a completed job, or None if it has not completed (missing, partial or foreign file)."""
    try:
        metrics = json.loads((job_dir / "metrics.json").read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(metrics, dict) or any(k not in metrics for k in METRIC_COLUMNS):
        return None
    return metrics


def run_job(job: Job, jobs_dir: str) -> JobResult:
    """Run one job in this process: ``run_scenario(..., record=False)`` into ``jobs_dir/<job_id>/``.

    This is the function workers execute. A job's exception is its result (``status="failed"``), not the sweep's.
    """
    job_dir = Path(jobs_dir) / job.job_id
    try:
        from rover_sim.scenario.schema import Scenario

        scenario = Scenario.model_validate(job.scenario)
        from rover_sim.runtime.run import run_scenario

        metrics = run_scenario(scenario, job_dir, record=False)
        return JobResult(job.job_id, "ok", metrics=metrics.deterministic_dict())  # = its metrics.json
    except Exception as e:  # noqa: BLE001 - isolation boundary: any failure of one job is reported, the sweep goes on
        (job_dir / "metrics.json").unlink(missing_ok=True)  # outputs written before the failure are not a result
        return failed_result(job, e)


def failed_result(job: Job, error: BaseException, why: str = "") -> JobResult:
    """A failed result: the error on one line (for results.csv) and the full traceback (for error.json)."""
    text = "; ".join(line.strip() for line in f"{why}{type(error).__name__}: {error}".splitlines() if line.strip())
    return JobResult(job.job_id, "failed", error=text, traceback="".join(traceback.format_exception(error)))


def _record(jobs_dir: Path, job: Job, result: JobResult) -> None:
    """Client side: metrics.json for a finished job (workers may not share our disk), error.json for a failed one."""
    job_dir = jobs_dir / job.job_id
    if result.ok:
        _write_json(job_dir / "metrics.json", result.metrics)
        (job_dir / "error.json").unlink(missing_ok=True)
    else:
        (job_dir / "metrics.json").unlink(missing_ok=True)
        _write_json(
            job_dir / "error.json",
            {
                "job_id": job.job_id,
                "params": job.params,
                "seed": job.seed,
                "error": result.error,
                "traceback": result.traceback,
            },
        )


# ------------------------------------------------------------------------------------------------- executors
# Each yields (job, result) as jobs finish.


def _run_in_process(jobs: Sequence[Job], jobs_dir: str, job_fn: JobFn) -> Iterator[tuple[Job, JobResult]]:
    """One job after another in this process. The mission loop turns Ctrl-C into a partial result; here Ctrl-C
    must stop the sweep instead and leave that job to be run again, so a SIGINT/SIGTERM handler notes it first."""
    import signal
    import threading

    from rover_sim.errors import Terminated

    interrupted: list[type[KeyboardInterrupt]] = []

    def on_signal(signum, frame) -> None:  # SIGTERM (errors.Terminated) is handled like Ctrl-C
        interrupted.append(Terminated if signum == signal.SIGTERM else KeyboardInterrupt)
        raise interrupted[-1]

    in_main = threading.current_thread() is threading.main_thread()
    for job in jobs:
        previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)} if in_main else {}
        try:
            result = job_fn(job, jobs_dir)
        except KeyboardInterrupt:
            (Path(jobs_dir) / job.job_id / "metrics.json").unlink(missing_ok=True)
            raise
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
        if interrupted:
            (Path(jobs_dir) / job.job_id / "metrics.json").unlink(missing_ok=True)
            raise interrupted[-1]
        yield job, result


def init_worker() -> None:
    """Pool-worker start-up: thread limits before numpy loads (see :data:`WORKER_THREAD_ENV`); Ctrl-C ignored
    (the parent stops the sweep and terminates its workers, so no job records a half-run mission as done)."""
    import signal

    for k, v in WORKER_THREAD_ENV.items():
        os.environ.setdefault(k, v)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_on_pool(jobs: Sequence[Job], jobs_dir: str, job_fn: JobFn, workers: int) -> Iterator[tuple[Job, JobResult]]:
    """A local ``spawn`` process pool: each worker imports rover_sim afresh, none inherits a GL context."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=ctx, initializer=init_worker)
    finished = False
    try:
        futures = {pool.submit(job_fn, job, jobs_dir): job for job in jobs}
        for fut in as_completed(futures):
            job = futures[fut]
            try:
                yield job, fut.result()
            except BrokenProcessPool as e:
                yield (
                    job,
                    failed_result(
                        job,
                        e,
                        "a worker process crashed, taking this job with it (re-run the sweep "
                        "to retry; completed jobs are skipped): ",
                    ),
                )
            except Exception as e:  # noqa: BLE001 - e.g. a result that cannot be pickled: this job fails, not all
                yield job, failed_result(job, e)
        finished = True
    finally:
        if finished:
            pool.shutdown(wait=True)
        else:  # Ctrl-C or an error in the caller: stop now rather than wait for the running jobs
            processes = list((getattr(pool, "_processes", None) or {}).values())  # no public API before 3.14
            pool.shutdown(wait=False, cancel_futures=True)
            for proc in processes:
                proc.terminate()


def _run_on_dask(jobs: Sequence[Job], jobs_dir: str, job_fn: JobFn, scheduler: str) -> Iterator[tuple[Job, JobResult]]:
    """Submit every job to a Dask cluster (``retries=2``: a task whose worker dies runs again elsewhere)."""
    try:
        from distributed import Client, as_completed
    except ImportError as e:
        raise DaskUnavailable(str(e)) from None
    try:
        client = Client(scheduler, timeout=DASK_CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as e:
        raise SchedulerUnreachable(scheduler, f"{type(e).__name__}: {e}") from None
    try:
        token = uuid.uuid4().hex[:8]  # fresh keys: never pick up another sweep's cached task on a shared cluster
        futures = {
            client.submit(
                job_fn, job, jobs_dir, key=f"rover-sim-{job.job_id}-{token}", retries=DASK_RETRIES, pure=False
            ): job
            for job in jobs
        }
        for fut in as_completed(futures):
            job = futures[fut]
            if fut.status == "finished":
                yield job, fut.result()
            else:
                try:
                    err = fut.exception()
                except Exception as e:  # noqa: BLE001 - a cancelled future raises instead of returning its error
                    err = e
                yield job, failed_result(job, err, f"Dask task {fut.status} (retries: {DASK_RETRIES}): ")
    finally:
        client.close()


# ------------------------------------------------------------------------------------------------- the sweep


def default_workers() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def run_jobs(
    jobs: Sequence[Job],
    jobs_dir: Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    job_fn: JobFn = run_job,
    on_result: OnResult = _no_progress,
    reuse: bool = True,
) -> list[JobResult]:
    """Steps 2-3 of :func:`run_sweep` for any list of jobs (several scenarios may share one list): each job's
    ``job.json`` is written, a completed job is read back instead of run again (``reuse``), the rest run on the
    executor. Results in ``jobs`` order; the same whatever the executor or worker count (each job is its own run)."""
    jobs_dir.mkdir(parents=True, exist_ok=True)
    results: dict[str, JobResult] = {}
    for job in jobs:
        _write_json(
            jobs_dir / job.job_id / "job.json",
            {"job_id": job.job_id, "params": job.params, "seed": job.seed, "scenario": job.scenario},
        )
        done = load_completed(jobs_dir / job.job_id) if reuse else None
        if done is not None:
            results[job.job_id] = JobResult(job.job_id, "ok", metrics=done, cached=True)
            on_result(len(results), len(jobs), job, results[job.job_id])
    pending = [j for j in jobs if j.job_id not in results]
    n_workers = default_workers() if workers is None else workers
    if not pending:
        stream: Iterator[tuple[Job, JobResult]] = iter(())
    elif scheduler is not None:
        stream = _run_on_dask(pending, str(jobs_dir), job_fn, scheduler)
    elif n_workers <= 0:
        stream = _run_in_process(pending, str(jobs_dir), job_fn)
    else:
        stream = _run_on_pool(pending, str(jobs_dir), job_fn, n_workers)
    for job, result in stream:
        _record(jobs_dir, job, result)
        results[job.job_id] = result
        on_result(len(results), len(jobs), job, result)
    return [results[j.job_id] for j in jobs]


def run_sweep(
    scenario: str | Path,
    grid: Sequence[str | GridAxis],
    seeds: int | Iterable[int],
    out_dir: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    overrides: Sequence[str] = (),
    on_result: OnResult = _no_progress,
    job_fn: JobFn = run_job,
    plots: bool = True,
) -> SweepResult:
    """Run ``scenario`` over the cartesian product of ``grid`` times ``seeds`` into ``out_dir``; see the module doc.

    ``workers``: local processes (default: the CPUs this process may use; 0 runs every job in this process).
    ``scheduler``: a Dask scheduler address; the jobs run there instead of locally.
    ``job_fn``: what runs one job; a module-level function (workers import it by name), :func:`run_job` by default.
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    jobs_dir = out / "jobs"
    axes = [g if isinstance(g, GridAxis) else parse_grid(g) for g in grid]
    jobs = plan_jobs(scenario, axes, seeds, overrides)
    jobs_dir.mkdir(parents=True, exist_ok=True)
    _write_json(
        out / "sweep.json",
        {
            "scenario": str(scenario),
            "grid": {a.key: list(a.raw) for a in axes},
            "overrides": list(overrides),
            "seeds": sorted({j.seed for j in jobs}),
            "jobs": {j.job_id: {"params": j.params, "seed": j.seed} for j in jobs},
        },
    )
    ordered = run_jobs(jobs, jobs_dir, workers=workers, scheduler=scheduler, job_fn=job_fn, on_result=on_result)
    csv_path = write_results_csv(out / "results.csv", axes, jobs, ordered)
    plot_paths = plot_sweep(out / "plots", axes, jobs, ordered) if plots else []
    return SweepResult(out, axes, jobs, ordered, time.perf_counter() - t0, csv_path, plot_paths)


# ------------------------------------------------------------------------------------------------- results.csv


def result_columns(axes: Sequence[GridAxis]) -> list[str]:
    return ["job_id", *[a.key for a in axes], *METRIC_COLUMNS, "status", "error"]


def _cell(v: Any) -> Any:
    if v is None:
        return ""
    return json.dumps(v) if isinstance(v, list | dict) else v


def write_results_csv(path: Path, axes: Sequence[GridAxis], jobs: Sequence[Job], results: Sequence[JobResult]) -> Path:
    """One row per job, in grid order: job_id, the grid values, the metrics, status and error."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(result_columns(axes))
        for job, res in zip(jobs, results, strict=True):
            m = res.metrics or {"scenario": job.scenario.get("name"), "seed": job.seed}
            w.writerow(
                [
                    job.job_id,
                    *[_cell(job.params[a.key]) for a in axes],
                    *[_cell(m.get(k)) for k in METRIC_COLUMNS],
                    res.status,
                    res.error or "",
                ]
            )
    os.replace(tmp, path)
    return path


def read_results_csv(path: str | Path) -> list[dict[str, str]]:
    with Path(path).open(newline="") as f:
        return list(csv.DictReader(f))
