"""Run outputs: ``metrics.json``, ``timing.json``, ``scenario.json``, ``events.log``, trajectories, plots; and
:func:`run_scenario`, the one call that loads, runs and writes a scenario."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from nav.trajectory import write_tum
from rover_sim.io.recording import NullRecorder, Recorder
from rover_sim.mission.evaluator import Metrics
from rover_sim.mission.pipeline import Mission
from rover_sim.mission.scenario import Scenario


def save_terrain_npz(terrain, heights_m: np.ndarray, path: Path) -> None:
    """``heights_m[i, j]`` is the height at x = x0_m + j cell_size_m, y = y0_m + i cell_size_m (world metres)."""
    np.savez(
        path,
        heights_m=np.asarray(heights_m, dtype=float),
        x0_m=float(-terrain.half_x_m),
        y0_m=float(-terrain.half_y_m),
        cell_size_m=float(terrain.cell_size_m),
    )


def write_outputs(mission: Mission, metrics: Metrics, out_dir: Path) -> None:
    """metrics.json, trajectories/*.tum, plots/*.png, scenario.json (the resolved config) and events.log."""
    from rover_sim.io import plots

    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "metrics.json").write_text(json.dumps(metrics.deterministic_dict(), indent=2))
    (out_dir / "timing.json").write_text(json.dumps(metrics.timing | {"wall_s": metrics.wall_s}, indent=2))
    (out_dir / "scenario.json").write_text(json.dumps(mission.sc.resolved_dict(), indent=2))
    (out_dir / "events.log").write_text("\n".join(mission.events) + "\n")
    save_terrain_npz(mission.terrain, mission.terrain.heights_m, out_dir / "terrain_before.npz")
    save_terrain_npz(mission.terrain, mission.sim.terrain_heights_m(), out_dir / "terrain_after.npz")
    tdir = out_dir / "trajectories"
    tdir.mkdir(exist_ok=True)
    trajs = mission.trajectories()
    for name, tr in trajs.items():
        write_tum(tr, tdir / f"{name}.tum")
    pdir = out_dir / "plots"
    pdir.mkdir(exist_ok=True)
    truth = trajs["truth"]
    dist = truth.cumulative_distance_m()
    errors = {
        n: np.linalg.norm(t.positions_xyz - truth.positions_xyz, axis=1) for n, t in trajs.items() if n != "truth"
    }
    if len(truth) > 1:
        plots.plot_error_vs_distance(dist, errors, pdir / "error_vs_distance.png", title=mission.sc.name)
    keep = [(z.name, z.x_m, z.y_m, z.radius_m) for z in mission.sc.keep_out]
    plots.plot_paths(
        mission.terrain,
        {n: t.positions_xyz for n, t in trajs.items()},
        pdir / "paths.png",
        keep_out=keep,
        title=mission.sc.name,
    )
    if mission.vo_steps:
        ts = np.array([s.t_s for s in mission.vo_steps])
        plots.plot_slip(
            ts,
            {
                "truth": np.array([s.true_slip for s in mission.vo_steps]),
                "VO": np.array([s.vo_slip for s in mission.vo_steps]),
            },
            pdir / "slip.png",
        )


def run_scenario(
    scenario: str | Path | Scenario,
    out_dir: Path | None,
    seed: int | None = None,
    overrides: list[str] | None = None,
    record: bool = True,
    progress: bool = False,
) -> Metrics:
    """Load, run and write one scenario. Ctrl-C or a physics divergence still leaves a valid recording and
    partial metrics (``passed`` false, ``reason`` says why)."""
    from rover_sim.io.recording import RerunRecorder
    from rover_sim.mission.scenario import load_scenario

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides, seed)
    if out_dir is not None:
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
    rec: Recorder = (
        RerunRecorder(out_dir / "recording.rrd", recording_name=sc.name) if (record and out_dir) else NullRecorder()
    )
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(
            desc=sc.name, unit="sim-s", mininterval=1.0, bar_format="{desc}: {n:.0f} sim-s [{elapsed}, {rate_fmt}]"
        )

    def on_progress(t_s: float, _msg: str) -> None:
        if bar is not None and t_s - bar.n >= 1.0:
            bar.update(t_s - bar.n)

    try:
        mission = Mission(sc, rec, on_progress)
        try:
            metrics = mission.run()
        finally:
            mission.close()
        if out_dir is not None:
            write_outputs(mission, metrics, out_dir)
    finally:
        if bar is not None:
            bar.close()
        rec.close()
    return metrics
