"""`rover-sim bench traverse`: sol-scale and kilometre drives on streamed terrain, with their bars.

Cases: the two sol scenarios of the catalogue (``spirit_plains_sol``, ``opportunity_record_sol``) and the
benchmark-only 1 km traverse (``benchmarks/traverse_1km.toml``). Each case runs in a fresh ``spawn`` process, so
its peak RSS (``ru_maxrss``) is its own; the RSS is also read when the true path first passes 100 m and at the end,
and every 50 m for the details JSON (``rss_trace_mb``: [true path m, RSS MB] pairs, to see where memory grows).
The recording is written (``recording.rrd``) and its size reported. Errors: dead reckoning and VO (final, % of the
distance; the 10 m KITTI segment error from metrics.json), the autonav outcome and the true distance to the goal.

Bars: :class:`rover_sim.runtime.acceptance.bars.TraverseBar` (1 km -- peak RSS <= 3 GB, RSS at the end within 15 % of
RSS after 100 m, recording <= 150 MB, real-time factor >= 15; spirit_plains_sol -- goal reached, no contact with a
rock >= 25 cm, DR 1-6 %; opportunity_record_sol -- >= 200 m in its time budget), judged by
:func:`~rover_sim.runtime.acceptance.bars.traverse_verdict`.
"""

from __future__ import annotations

import resource
import time
from pathlib import Path

from rover_sim.bench import write_json
from rover_sim.errors import ConfigError
from rover_sim.resources import data_dir, scenarios_dir
from rover_sim.runtime.acceptance import bars

BENCH_DIR = data_dir("benchmarks")
CASES = {
    "spirit_plains_sol": scenarios_dir() / "spirit_plains_sol.toml",
    "opportunity_record_sol": scenarios_dir() / "opportunity_record_sol.toml",
    "traverse_1km": BENCH_DIR / "traverse_1km.toml",
}
RSS_PROBE_M = 100.0
RSS_TRACE_M = 50.0  # the details JSON samples RSS every this much true path (rss_trace_mb)


def rss_mb() -> float:
    """Resident set size of this process now (Linux ``/proc/self/status``), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def run_case(name: str, out_dir: str, overrides: tuple[str, ...] = ()) -> dict:
    """One case in this process (a spawn worker): run, write outputs, measure; the row of the table."""
    import numpy as np

    from rover_sim.io.recording import RerunRecorder
    from rover_sim.runtime.run import sol_recording, write_outputs
    from rover_sim.runtime.runner import Mission
    from rover_sim.scenario.loading import load_scenario

    sc = load_scenario(CASES[name], list(overrides))
    out = Path(out_dir) / name
    out.mkdir(parents=True, exist_ok=True)
    rec = RerunRecorder(out / "recording.rrd", recording_name=sc.name, **sol_recording(sc))
    t0, cpu0 = time.perf_counter(), time.process_time()
    mission = Mission(sc, rec)
    probe = {"path_m": 0.0, "last": None, "rss_100m_mb": None, "next_trace_m": 0.0}
    trace: list[tuple[float, float]] = []  # (true path m, RSS MB) every RSS_TRACE_M: where memory grows

    def on_tick(_obs: object, truth: object) -> None:
        p = truth.position_xyz_m  # type: ignore[attr-defined]
        if probe["last"] is not None:
            probe["path_m"] += float(np.linalg.norm(p[:2] - probe["last"]))
        probe["last"] = p[:2].copy()
        if probe["rss_100m_mb"] is None and probe["path_m"] >= RSS_PROBE_M:
            probe["rss_100m_mb"] = round(rss_mb(), 1)
        if probe["path_m"] >= probe["next_trace_m"]:
            trace.append((round(probe["path_m"], 1), round(rss_mb(), 1)))
            probe["next_trace_m"] += RSS_TRACE_M

    mission.tick_listeners.append(on_tick)
    try:
        metrics = mission.run()
    finally:
        mission.close()
    write_outputs(mission, metrics, out)
    rec.close()
    wall_s, cpu_s = time.perf_counter() - t0, time.process_time() - cpu0
    onboard_goal = None
    if mission.evaluator.goal_xy is not None:
        onboard_goal = float(np.linalg.norm(mission.onboard.pose.position_xyz_m[:2] - mission.evaluator.goal_xy))
    kitti = metrics.extra.get("kitti_translation_error_pct", {})
    return {
        "name": name,
        "distance_m": round(metrics.distance_m, 2),
        "wall_s": round(wall_s, 1),
        "realtime_factor": round(metrics.sim_s / max(wall_s, 1e-9), 1),
        "cpu_s": round(cpu_s, 1),  # on a shared machine: the real-time factor one free core would give
        "realtime_factor_cpu": round(metrics.sim_s / max(cpu_s, 1e-9), 1),
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
        "rss_100m_mb": probe["rss_100m_mb"],
        "rss_end_mb": round(rss_mb(), 1),
        "rss_trace_mb": trace,
        "recording_mb": round((out / "recording.rrd").stat().st_size / 1e6, 2),
        "dr_error_pct": metrics.dr_error_pct,
        "vo_error_pct": metrics.vo_error_pct,
        "dr_10m_segment_pct": kitti.get("dead_reckoning", {}).get("10m"),
        "goal_distance_m": metrics.goal_distance_m,
        "onboard_goal_distance_m": None if onboard_goal is None else round(onboard_goal, 3),
        "tall_rock_contacts": metrics.tall_rock_contacts,
        "body_collisions": metrics.body_collisions,
        "autonav": metrics.extra.get("autonav"),
        "sol": metrics.extra.get("sol"),
        "sim_s": metrics.sim_s,
        "reason": metrics.reason,
    }


def _run_isolated(name: str, out_dir: str, overrides: tuple[str, ...]) -> dict:
    """``run_case`` in a fresh spawn process (never fork: the renderer holds a GL context)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from rover_sim.apps.sweep import init_worker

    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=ctx, initializer=init_worker) as pool:
        return pool.submit(run_case, name, out_dir, overrides).result()


PUBLIC_KEYS = ("name", "distance_m", "wall_s", "realtime_factor", "peak_rss_mb", "rss_100m_mb", "recording_mb",
               "dr_error_pct", "vo_error_pct", "goal_distance_m", "passed")  # fmt: skip


def bench_traverse(
    json_path: str | None = None, out_dir: str = "runs/bench_traverse", cases: list[str] | None = None,
    overrides: tuple[str, ...] = (),
) -> dict:  # fmt: skip
    """Run the cases (each in its own process), print the table, write ``{"cases": [...]}`` JSON."""
    names = cases or list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        raise ConfigError("--case", ", ".join(unknown), f"unknown traverse case; choose from {', '.join(CASES)}")
    rows = []
    print("| case | distance m | wall s | real-time x | peak RSS MB | RSS@100 m MB | RSS end MB | recording MB | "
          "DR % | DR 10 m seg % | VO % | goal m (truth / onboard) | passed |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for name in names:
        row = _run_isolated(name, out_dir, overrides)
        verdict = bars.traverse_verdict(row)  # the one judge: this table, the JSON, the JUnit, the exit status
        row["passed"], row["why"] = verdict.passed, "; ".join(verdict.reasons)
        rows.append(row)
        print(f"| {name} | {row['distance_m']:.1f} | {row['wall_s']:.0f} | {row['realtime_factor']:.1f} | "
              f"{row['peak_rss_mb']:.0f} | {row['rss_100m_mb']} | {row['rss_end_mb']:.0f} | "
              f"{row['recording_mb']:.1f} | "
              f"{row['dr_error_pct']} | {row['dr_10m_segment_pct']} | {row['vo_error_pct']} | "
              f"{row['goal_distance_m']} / {row['onboard_goal_distance_m']} | "
              f"{verdict.cell()} |", flush=True)  # fmt: skip
    result = {"cases": [{k: r[k] for k in PUBLIC_KEYS} for r in rows]}
    write_json(json_path, result)
    if json_path:
        write_json(str(Path(json_path).with_suffix(".details.json")), {"cases": rows})
    return result | {"details": rows}
