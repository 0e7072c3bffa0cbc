"""Run outputs: ``metrics.json``, ``timing.json``, ``scenario.json``, ``events.log``, trajectories, plots; and
:func:`run_scenario`, the one call that loads, runs and writes a scenario."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from nav.trajectory import write_tum
from rover_sim import interrupts
from rover_sim.io.blueprint import RunLayout, blueprint_for
from rover_sim.io.progress import SimProgress
from rover_sim.io.recorder_protocol import NullRecorder, Recorder
from rover_sim.runtime.evaluator import Metrics, step_slips
from rover_sim.runtime.runner import Mission
from rover_sim.scenario.commands import AutonavCmd
from rover_sim.scenario.schema import Scenario


def layout_of(sc: Scenario) -> RunLayout:
    """What the recording of ``sc`` will hold, for its viewer layout."""
    return RunLayout(
        vo_camera=sc.nav.camera if sc.nav.vo.enabled else None,
        autonav=any(isinstance(c, AutonavCmd) for c in sc.commands),
    )


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
    if mission.sim.deform is not None:  # only with [physics] deformable = true (opt-in)
        save_terrain_npz(mission.terrain, mission.terrain.heights_m, out_dir / "terrain_before.npz")
        save_terrain_npz(mission.terrain, mission.sim.terrain_heights_m(), out_dir / "terrain_after.npz")
    tdir = out_dir / "trajectories"
    tdir.mkdir(exist_ok=True)
    trajs = mission.trajectories()
    for name, tr in trajs.items():
        write_tum(tr, tdir / f"{name}.tum")
    keep = [(z.name, z.x_m, z.y_m, z.radius_m) for z in mission.sc.keep_out]
    t_s, true_slip, vo_slip = step_slips(mission.vo_steps)  # the samples max_slip_pct is taken over
    plots.plot_run(
        out_dir / "plots",
        plots.run_title(mission.sc.name, mission.sc.seed, mission.sc.sensors.profile),
        mission.terrain,
        trajs,
        keep_out=keep,
        slip=(t_s, {"truth": true_slip, "vo": vo_slip}),
    )


def setup_interrupted(sc: Scenario, exc: KeyboardInterrupt, wall_s: float) -> Metrics:
    """The metrics of a run stopped before its loop started (nothing measured: ``None``)."""
    return Metrics(
        scenario=sc.name,
        seed=sc.seed,
        distance_m=0.0,
        dr_error_pct=None,
        vo_error_pct=None,
        vo_convergence_pct=None,
        max_slip_pct=None,  # type: ignore[arg-type]
        mean_slip_pct=None,  # type: ignore[arg-type]
        passed=False,
        reason=f"run did not complete: {interrupts.describe(exc, 'during setup')}",
        wall_s=round(wall_s, 2),
        dr_error_m=None,  # type: ignore[arg-type]
    )


def write_setup_outputs(sc: Scenario, metrics: Metrics, out_dir: Path) -> None:
    """What a run stopped during setup can write: metrics.json (a stub), timing.json, scenario.json, events.log."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "metrics.json").write_text(json.dumps(metrics.deterministic_dict(), indent=2))
    (out_dir / "timing.json").write_text(json.dumps({"wall_s": metrics.wall_s}, indent=2))
    (out_dir / "scenario.json").write_text(json.dumps(sc.resolved_dict(), indent=2))
    (out_dir / "events.log").write_text(f"[    0.00s] ERROR: {metrics.reason.removeprefix('run did not complete: ')}\n")


def discard_failed_start(rec: Recorder, out_dir: Path | None, created_dir: bool) -> None:
    """Remove what a run that failed to start wrote: its recording, and ``out_dir`` if the run created it and it is
    empty now (the identical command can then be run again once the cause is fixed)."""
    rec.close()
    if out_dir is None:
        return
    (out_dir / "recording.rrd").unlink(missing_ok=True)
    if created_dir and not any(out_dir.iterdir()):
        out_dir.rmdir()


SOL_TRACK_SPACING_M = 0.1  # a sol's drive: track vertices 10 cm apart ...
SOL_TRACK_BLOCK_POINTS = 32  # ... in short blocks, so each track update re-sends little (recording ~ distance)
SOL_MAX_POINTS = 2000  # stereo point clouds subsampled to this: 24 kB a VO step (a full navcam cloud is ~600 kB)


def sol_recording(sc: Scenario) -> dict:
    """Recorder settings that keep a sol-scale drive's recording compact (none for other scenarios)."""
    if sc.sol is None:
        return {}
    return {
        "min_spacing_m": SOL_TRACK_SPACING_M,
        "segment_points": SOL_TRACK_BLOCK_POINTS,
        "max_points": SOL_MAX_POINTS,
    }


def run_scenario(
    scenario: str | Path | Scenario,
    out_dir: Path | None,
    seed: int | None = None,
    overrides: list[str] | None = None,
    record: bool = True,
    progress: bool = False,
    reraise_interrupt: bool = False,
    attach: Callable[[Mission], None] | None = None,
) -> Metrics:
    """Load, run and write one scenario. Ctrl-C, SIGTERM (see :mod:`rover_sim.interrupts`) or a physics divergence
    still leaves a valid recording and partial metrics (``passed`` false, ``reason`` says why); so does an
    interrupt while the world is being built ("interrupted during setup"). With ``reraise_interrupt`` the
    interrupt is raised again once the outputs are written (a benchmark stops instead of going on). ``attach`` is
    called with the built mission before it runs (listeners on its public hooks: exporters, replayed estimators)."""
    import time

    with interrupts.sigterm_raises():
        return _run(
            scenario, out_dir, seed, overrides, record, progress, reraise_interrupt, time.perf_counter(), attach
        )


def _run(
    scenario: str | Path | Scenario,
    out_dir: Path | None,
    seed: int | None,
    overrides: list[str] | None,
    record: bool,
    progress: bool,
    reraise_interrupt: bool,
    t0: float,
    attach: Callable[[Mission], None] | None = None,
) -> Metrics:
    import time

    from rover_sim.io.recording import RerunRecorder
    from rover_sim.scenario.loading import load_scenario

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides, seed)
    created_dir = False
    if out_dir is not None:
        out_dir = Path(out_dir)
        created_dir = not out_dir.exists()
        out_dir.mkdir(parents=True, exist_ok=True)
    # the recording file must not exist without the code below that finishes it on an interrupt
    with interrupts.deferred() as pending:
        rec: Recorder = (
            RerunRecorder(
                out_dir / "recording.rrd",
                recording_name=sc.name,
                blueprint=blueprint_for(layout_of(sc)),
                **sol_recording(sc),
            )  # fmt: skip
            if (record and out_dir)
            else NullRecorder()
        )
        bar = SimProgress(sc.name) if progress else None  # a bar on a terminal, plain lines in a log

    def on_progress(t_s: float, _msg: str) -> None:
        if bar is not None:
            bar.update(t_s)

    try:
        try:
            if pending.exc is not None:
                raise pending.exc
            mission = Mission(sc, rec, on_progress)
            if attach is not None:
                try:
                    attach(mission)
                except BaseException:  # a listener that cannot start: release the renderer's GL context
                    mission.close()
                    raise
        except KeyboardInterrupt as e:  # Ctrl-C or SIGTERM while the world was being built
            metrics = setup_interrupted(sc, e, time.perf_counter() - t0)
            rec.log_event(0.0, 0, metrics.reason, "ERROR")
            if out_dir is not None:
                write_setup_outputs(sc, metrics, out_dir)
            if reraise_interrupt:
                raise
            return metrics
        except Exception:  # the mission could not start (e.g. a plugin does not load): leave no files behind
            discard_failed_start(rec, out_dir, created_dir)
            raise
        try:
            metrics = mission.run()
        finally:
            mission.close()
        if out_dir is not None:
            write_outputs(mission, metrics, out_dir)
        if reraise_interrupt and mission.interrupted is not None:
            raise mission.interrupted
    finally:
        if bar is not None:
            bar.close()
        rec.close()
    return metrics
