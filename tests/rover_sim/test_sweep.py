"""Monte-Carlo sweeps: grid planning, job ids, skip-completed, failure isolation, the local pool and Dask.

The physics tests run a tiny scenario (6 m x 6 m at 0.1 m, no VO, one 0.5 m drive: about a second per job). The
fake job functions below are module-level so spawned pool workers can import them by name.
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from pathlib import Path

import pytest

import rover_sim  # noqa: F401  (first: sets MUJOCO_GL=egl before anything imports mujoco)
from rover_sim.apps import sweep
from rover_sim.apps.sweep import (
    METRIC_COLUMNS,
    load_completed,
    parse_grid,
    plan_jobs,
    read_results_csv,
    result_columns,
    run_sweep,
)
from rover_sim.apps.sweep_jobs import Job, JobResult
from rover_sim.errors import ConfigError, DaskUnavailable, SchedulerUnreachable

TINY_TOML = """
name = "tiny_sweep"

[terrain]
size_m = [6, 6]
cell_size_m = 0.1
slope = { slope_deg = 10, azimuth_deg = 0 }
roughness = { rms_m = 0.0 }
rocks = { cover_fraction = 0.0 }
material = { kind = "sand" }

[nav]
vo = false

[[commands]]
type = "drive"
distance_m = 0.5
"""
GRID = ["terrain.slope.slope_deg=5,15", "terrain.material.kind=sand,bedrock"]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("scenario") / "tiny_sweep.toml"
    path.write_text(TINY_TOML)
    return path


# ------------------------------------------------------------------------------------------------- fake jobs


def fake_job(job: Job, jobs_dir: str) -> JobResult:
    """Instant stand-in for run_job: metrics derived from the config."""
    slope = job.scenario["terrain"]["slope"]["slope_deg"]
    m = {k: None for k in METRIC_COLUMNS} | {
        "scenario": job.scenario["name"],
        "seed": job.seed,
        "max_slip_pct": 2.0 * slope,
        "dr_error_pct": slope,
        "passed": True,
        "reason": "fake",
        "wall_s": 0.0,
        "distance_m": 1.0,
        "mean_slip_pct": slope,
    }
    return JobResult(job.job_id, "ok", metrics=m)


def fail_on_seed_1(job: Job, jobs_dir: str) -> JobResult:
    if job.seed == 1:
        from rover_sim.apps.sweep import run_job

        bad = Job(job.job_id, job.params, job.seed, job.scenario | {"commands": []})  # fails validation in the worker
        return run_job(bad, jobs_dir)
    return fake_job(job, jobs_dir)


def crash_on_seed_1(job: Job, jobs_dir: str) -> JobResult:
    if job.seed == 1:
        time.sleep(0.3)  # let the other worker pick up work first
        os._exit(3)  # a segfault-like death: no exception, no result
    return fake_job(job, jobs_dir)


# ------------------------------------------------------------------------------------------------- planning


def test_parse_grid_values_are_toml() -> None:
    a = parse_grid("terrain.slope.slope_deg=10, 15.5,20")
    assert a.key == "terrain.slope.slope_deg" and a.values == (10, 15.5, 20) and a.raw == ("10", "15.5", "20")
    assert parse_grid("terrain.material.kind=sand,bedrock").values == ("sand", "bedrock")
    assert parse_grid('terrain.size_m=[6,6],[8,6],"x,y"').values == ([6, 6], [8, 6], "x,y")
    for bad in ("terrain.slope.slope_deg", "seed=1,2", "a.b=1,,2", "a.b=1,1"):
        with pytest.raises(ConfigError):
            parse_grid(bad)


def test_plan_is_the_cartesian_product_times_seeds_with_stable_ids(tiny) -> None:
    jobs = plan_jobs(tiny, [parse_grid(g) for g in GRID], 2)
    assert len(jobs) == 8
    assert [(j.params["terrain.slope.slope_deg"], j.params["terrain.material.kind"], j.seed) for j in jobs[:3]] == [
        (5, "sand", 0),
        (5, "sand", 1),
        (5, "bedrock", 0),
    ]
    assert jobs[0].scenario["terrain"]["slope"]["slope_deg"] == 5 and jobs[1].scenario["seed"] == 1
    assert len({j.job_id for j in jobs}) == 8
    again = plan_jobs(tiny, [parse_grid(g) for g in GRID], 2)
    assert [j.job_id for j in again] == [j.job_id for j in jobs]  # stable across calls (and processes: sha256)
    # the same resolved config is the same job, however it is spelt
    assert len(plan_jobs(tiny, [parse_grid("terrain.slope.slope_deg=10,10.0")], 1)) == 1
    # a base --set changes every job's id
    other = plan_jobs(tiny, [parse_grid(GRID[0])], 1, overrides=["commands.0.distance_m=0.4"])
    assert not {j.job_id for j in other} & {j.job_id for j in jobs}


def test_bad_grid_value_fails_before_anything_runs(tiny, tmp_path) -> None:
    with pytest.raises(ConfigError, match="slope_deg"):
        run_sweep(tiny, ["terrain.slope.slope_deg=10,60"], 1, tmp_path / "out", job_fn=fake_job, workers=0)
    with pytest.raises(ConfigError, match="two --grid"):
        plan_jobs(tiny, [parse_grid("nav.vo=true"), parse_grid("nav.vo=false")], 1)
    assert not (tmp_path / "out" / "jobs").exists()


def test_load_completed_rejects_partial_metrics(tmp_path) -> None:
    assert load_completed(tmp_path) is None
    (tmp_path / "metrics.json").write_text('{"scenario": "x", "seed": 0, "distance')  # killed mid-write
    assert load_completed(tmp_path) is None
    (tmp_path / "metrics.json").write_text(json.dumps({k: 1 for k in METRIC_COLUMNS}))
    assert load_completed(tmp_path) is not None


# ------------------------------------------------------------------------------------------------- failures


def test_failed_job_is_reported_with_its_config_and_does_not_lose_the_others(tiny, tmp_path) -> None:
    res = run_sweep(tiny, [GRID[0]], 3, tmp_path, workers=2, job_fn=fail_on_seed_1)
    assert [r.status for r in res.results] == ["ok", "failed", "ok"] * 2
    rows = read_results_csv(tmp_path / "results.csv")
    assert list(rows[0]) == result_columns(res.axes)
    failed = [r for r in rows if r["status"] == "failed"]
    assert len(failed) == 2 and all(r["seed"] == "1" and r["scenario"] == "tiny_sweep" for r in failed)
    assert all(r["error"].startswith("ValidationError") and "commands" in r["error"] for r in failed)
    assert all("\n" not in r["error"] for r in failed)  # one line per job in the table
    assert {r["terrain.slope.slope_deg"] for r in failed} == {"5", "15"}
    err = json.loads((tmp_path / "jobs" / failed[0]["job_id"] / "error.json").read_text())
    assert err["seed"] == 1 and "Traceback" in err["traceback"]
    assert (tmp_path / "jobs" / failed[0]["job_id"] / "job.json").is_file()  # the config it ran
    # a re-run retries only the failed jobs
    again = run_sweep(tiny, [GRID[0]], 3, tmp_path, workers=2, job_fn=fake_job)
    assert again.n_run == 2 and again.n_cached == 4 and again.n_failed == 0
    assert not (tmp_path / "jobs" / failed[0]["job_id"] / "error.json").exists()


def test_crashed_pool_worker_fails_its_jobs_and_a_rerun_completes_them(tiny, tmp_path) -> None:
    first = run_sweep(tiny, [GRID[0]], 3, tmp_path, workers=2, job_fn=crash_on_seed_1, plots=False)
    assert first.n_failed >= 1
    crashed = [r for j, r in zip(first.jobs, first.results, strict=True) if j.seed == 1]
    assert crashed[0].status == "failed" and "crashed" in crashed[0].error
    assert all(r.error and "BrokenProcessPool" in r.error for r in first.results if not r.ok)
    second = run_sweep(tiny, [GRID[0]], 3, tmp_path, workers=2, job_fn=fake_job, plots=False)
    assert second.n_failed == 0 and second.n_run == first.n_failed and second.n_cached == 6 - first.n_failed
    assert len(read_results_csv(tmp_path / "results.csv")) == 6


def test_missing_dask_says_how_to_install_it(tiny, tmp_path, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    with pytest.raises(DaskUnavailable, match=r"rover-sim\[dask\]"):
        run_sweep(tiny, [GRID[0]], 1, tmp_path, scheduler="tcp://127.0.0.1:8786", job_fn=fake_job)


def test_unreachable_scheduler_is_a_clear_error(tiny, tmp_path, monkeypatch) -> None:
    pytest.importorskip("distributed", reason="the Dask backend needs the rover-sim[dask] extra")
    monkeypatch.setattr(sweep, "DASK_CONNECT_TIMEOUT_S", 0.5)
    with pytest.raises(SchedulerUnreachable, match="dask scheduler"):
        run_sweep(tiny, [GRID[0]], 1, tmp_path, scheduler="tcp://127.0.0.1:9", job_fn=fake_job)


# ------------------------------------------------------------------------------------------------- real runs


def _metrics_without_wall(res) -> dict[str, dict]:
    return {
        j.job_id: {k: v for k, v in r.metrics.items() if k != "wall_s"}
        for j, r in zip(res.jobs, res.results, strict=True)
    }


@pytest.fixture(scope="module")
def pool_sweep(tiny, tmp_path_factory):
    """The small sweep on the default local process pool (2 workers)."""
    out = tmp_path_factory.mktemp("pool")
    return run_sweep(tiny, GRID, 1, out, workers=2)


def test_pool_sweep_writes_results_metrics_and_plots(pool_sweep) -> None:
    res = pool_sweep
    assert res.n_failed == 0 and len(res.results) == 4
    rows = read_results_csv(res.csv_path)
    assert [r["job_id"] for r in rows] == [j.job_id for j in res.jobs]
    by = {(r["terrain.slope.slope_deg"], r["terrain.material.kind"]): float(r["max_slip_pct"]) for r in rows}
    assert by[("15", "sand")] > by[("5", "sand")] > by[("5", "bedrock")]  # steeper and softer slips more
    for j in res.jobs:
        assert load_completed(res.out_dir / "jobs" / j.job_id) is not None
        assert not (res.out_dir / "jobs" / j.job_id / "recording.rrd").exists()  # record=False
    assert {p.name for p in res.plots} == {"slip_vs_slope.png", "error_vs_slope.png", "slip_map.png"}
    assert all(p.stat().st_size > 1000 for p in res.plots)


def test_rerun_skips_completed_jobs(pool_sweep, tiny) -> None:
    again = run_sweep(tiny, GRID, 1, pool_sweep.out_dir, workers=2)
    assert again.n_run == 0 and again.n_cached == 4
    assert _metrics_without_wall(again) == _metrics_without_wall(pool_sweep)


@pytest.fixture(scope="module")
def dask_cluster():
    pytest.importorskip("distributed", reason="the Dask backend needs the rover-sim[dask] extra")
    import logging

    from distributed import LocalCluster

    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=logging.ERROR
    ) as cluster:
        yield cluster


def test_dask_cluster_gives_the_same_results_as_the_pool(pool_sweep, tiny, dask_cluster, tmp_path) -> None:
    res = run_sweep(tiny, GRID, 1, tmp_path, scheduler=dask_cluster.scheduler_address)
    assert res.n_failed == 0 and res.n_run == 4
    assert _metrics_without_wall(res) == _metrics_without_wall(pool_sweep)


def test_killing_a_dask_worker_mid_sweep_loses_nothing(tiny, dask_cluster, tmp_path) -> None:
    from distributed import Client

    killed: list[int] = []

    def kill_a_busy_worker() -> None:
        with Client(dask_cluster.scheduler_address, timeout=30) as client:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                busy = [w for w, keys in client.processing().items() if any("rover-sim-" in str(k) for k in keys)]
                if busy:
                    pid = client.run(os.getpid, workers=busy[:1])[busy[0]]
                    os.kill(pid, 9)
                    killed.append(pid)
                    return
                time.sleep(0.05)

    killer = threading.Thread(target=kill_a_busy_worker)
    killer.start()
    res = run_sweep(tiny, [GRID[0]], 2, tmp_path, scheduler=dask_cluster.scheduler_address, plots=False)
    killer.join()
    assert killed, "no worker was busy with a sweep job to kill"
    assert res.n_failed == 0 and len(res.results) == 4
    assert all(load_completed(tmp_path / "jobs" / j.job_id) is not None for j in res.jobs)
