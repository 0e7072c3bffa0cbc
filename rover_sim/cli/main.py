"""`rover-sim` command line: a thin layer over library functions (evo/kiss-icp style)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

import rover_sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported anywhere)
from rover_sim.cli.bench import bench_app
from rover_sim.cli.export import export_cmd
from rover_sim.cli.options import JunitOpt, PlannerOpt, SetOpt, StereoOpt, VoOpt, bad_input
from rover_sim.cli.orbital import bench_globalloc_cmd, orbital_cmd
from rover_sim.cli.preflight import preflight
from rover_sim.cli.scenarios import scenarios_cmd
from rover_sim.cli.status import finish, guarded
from rover_sim.cli.view import view_cmd
from rover_sim.errors import RoverSimError

app = typer.Typer(help="MER-class rover simulator with a MER-style navigation stack.", no_args_is_help=True)
app.add_typer(bench_app, name="bench")
app.command("view")(view_cmd)
app.command("scenarios")(scenarios_cmd)

RENDER_PX = (16, 2048)  # `render --resolution`: MuJoCo's offscreen buffer is allocated at this size


@app.command("check-gl")
def check_gl_cmd() -> None:
    """Check that offscreen rendering (EGL) works; prints the install hint if it does not."""
    from rover_sim.render.gl import check_gl

    try:
        check_gl()
    except RoverSimError as e:
        bad_input(e)
    typer.echo("offscreen rendering OK (MUJOCO_GL=egl)")


@app.command("render")
def render_cmd(
    scenario: Annotated[str, typer.Argument(help="Scenario whose terrain, sun and start pose to use.")],
    out: Annotated[Path, typer.Option("--out")] = Path("runs/render"),
    pair: Annotated[str, typer.Option(help="navcam | hazcam_front | hazcam_rear")] = "navcam",
    resolution: Annotated[int, typer.Option(help=f"Image side in pixels ({RENDER_PX[0]}..{RENDER_PX[1]}).")] = 256,
    seed: Annotated[int | None, typer.Option()] = None,
) -> None:
    """Write a stereo pair, its depth and the camera-model JSON at the scenario's start pose."""
    import math

    from rover_sim.bench.render import HAZCAM_PAIRS, render_to_dir
    from rover_sim.scenario.loading import load_scenario
    from rover_sim.sim.assembly import Sun

    pairs = ("navcam", *HAZCAM_PAIRS)
    if pair not in pairs:
        bad_input(ValueError(f"--pair {pair!r}: choose from {', '.join(pairs)}"))
    if not RENDER_PX[0] <= resolution <= RENDER_PX[1]:  # checked first: too large an offscreen buffer kills MuJoCo
        bad_input(ValueError(f"--resolution {resolution}: allowed {RENDER_PX[0]}..{RENDER_PX[1]} pixels"))
    preflight("render", dirs={"--out": out})
    try:
        sc = load_scenario(scenario, seed=seed)
    except RoverSimError as e:
        bad_input(e)
    st = sc.start
    files = render_to_dir(
        out,
        sc.terrain,
        (st.x_m, st.y_m, math.radians(st.yaw_deg)),
        which=pair,
        resolution=resolution,
        seed=sc.seed,
        mast_rad=(math.radians(sc.nav.mast_pan_deg), -math.radians(sc.nav.mast_tilt_deg)),
        sun=Sun(sc.sun.azimuth_deg, sc.sun.elevation_deg, sc.sun.shadows),
    )
    for name, path in files.items():
        typer.echo(f"{name}: {path}")


@app.command("run")
def run_cmd(
    scenario: Annotated[str, typer.Argument(help="Scenario name (scenarios/<name>.toml) or path to a TOML file.")],
    out: Annotated[
        Path | None, typer.Option("--out", help="Output directory [default: runs/latest, replaced by each run].")
    ] = None,
    seed: Annotated[int | None, typer.Option("--seed", help="Override the scenario seed.")] = None,
    set_: SetOpt = None,
    record: Annotated[bool, typer.Option("--record/--no-record", help="Write DIR/recording.rrd.")] = True,
    progress: Annotated[bool, typer.Option("--progress/--no-progress")] = True,
    vo: VoOpt = None,
    stereo: StereoOpt = None,
    planner: PlannerOpt = None,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Clear a non-empty --out directory first (its contents only).")
    ] = False,
    junit: JunitOpt = None,
) -> None:
    """Run a mission scenario: writes recording.rrd, metrics.json, trajectories/*.tum, plots/*.png.

    Exit status: 0 pass, 1 a criterion failed, 2 bad input, 3 run error, 130 Ctrl-C, 143 SIGTERM."""
    from rover_sim.cli.outdir import prepare_out_dir
    from rover_sim.io.junit import scenario_case

    if out is None:
        out, overwrite = Path("runs/latest"), True
    preflight("run", junit, dirs={"--out": out}, plugins={"vo": vo, "stereo": stereo, "planner": planner})
    with guarded(junit, "run"):
        from rover_sim.runtime.run import run_scenario
        from rover_sim.scenario.loading import load_scenario, plugin_overrides

        overrides = plugin_overrides(vo, stereo, planner) + list(set_ or [])
        sc = load_scenario(scenario, overrides, seed)  # bad input is reported before --out is touched
        prepare_out_dir(out, overwrite)
        metrics = run_scenario(sc, out, record=record, progress=progress)
    colour = typer.colors.GREEN if metrics.passed else typer.colors.RED
    typer.secho(f"{metrics.scenario}: {'PASS' if metrics.passed else 'FAIL'} ({metrics.reason})", fg=colour)

    def pct(v: float | None) -> str:
        return "-" if v is None else f"{v:.2f} %"

    typer.echo(
        f"distance {metrics.distance_m:.2f} m | DR error {pct(metrics.dr_error_pct)} | VO error "
        f"{pct(metrics.vo_error_pct)} | VO convergence {pct(metrics.vo_convergence_pct)} | max slip "
        f"{pct(metrics.max_slip_pct)}"
    )
    where = f"outputs in {out}/ (plots in {out}/plots/)"
    typer.echo(f"{where}; open the recording with: rover-sim view {out}" if record else where)
    finish(junit, "run", [scenario_case(metrics.deterministic_dict(), "run")])  # status: see rover_sim.cli.status


@app.command("demo")
def demo_cmd(out: Annotated[Path, typer.Option("--out")] = Path("runs/demo")) -> None:
    """The main job: the Wopmay scenario with a rerun recording, metrics and plots (replaces DIR's contents)."""
    run_cmd("wopmay", out=out, seed=None, set_=None, record=True, progress=True, overwrite=True)


@app.command("sweep")
def sweep_cmd(
    scenario: Annotated[str, typer.Argument(help="Scenario name (scenarios/<name>.toml) or path to a TOML file.")],
    grid: Annotated[
        list[str] | None,
        typer.Option("--grid", help="dotted.key=v1,v2,... (repeatable); jobs are the cartesian product x seeds."),
    ] = None,
    seeds: Annotated[int, typer.Option("--seeds", min=1, help="Run each grid point with seeds 0..N-1.")] = 1,
    out: Annotated[Path, typer.Option("--out", help="Output directory (re-running skips completed jobs).")] = Path(
        "runs/sweep"
    ),
    workers: Annotated[
        int | None, typer.Option("--workers", min=0, help="Local worker processes [default: CPUs]; 0: in this process.")
    ] = None,
    scheduler: Annotated[
        str | None, typer.Option("--scheduler", help="Dask scheduler tcp://host:port (needs rover-sim[dask]).")
    ] = None,
    set_: SetOpt = None,
) -> None:
    """Monte-Carlo sweep: DIR/results.csv (one row per job), DIR/plots/*.png, DIR/jobs/<job_id>/metrics.json."""
    preflight("sweep", dirs={"--out": out})
    from rover_sim.apps.sweep import run_sweep

    def report(done: int, total: int, job, result) -> None:
        if not result.ok:
            typer.secho(f"[{done}/{total}] FAILED {job.job_id} {job.label}: {result.error}", fg=typer.colors.RED)
            return
        m = result.metrics
        how = "done before" if result.cached else f"{m['wall_s']} s"
        vo = "-" if m["vo_error_pct"] is None else f"{m['vo_error_pct']} %"
        typer.echo(
            f"[{done}/{total}] ok {job.job_id} {job.label}: max slip {m['max_slip_pct']} %, DR error "
            f"{m['dr_error_pct']} %, VO error {vo} ({how})"
        )

    try:
        res = run_sweep(
            scenario,
            grid or [],
            seeds,
            out,
            workers=workers,
            scheduler=scheduler,
            overrides=set_ or [],
            on_result=report,
        )
    except RoverSimError as e:
        bad_input(e)
    colour = typer.colors.RED if res.n_failed else typer.colors.GREEN
    typer.secho(
        f"{len(res.jobs)} jobs: {res.n_run} run, {res.n_cached} done before, {res.n_failed} failed "
        f"({res.wall_s:.1f} s)",
        fg=colour,
    )
    typer.echo(f"results: {res.csv_path}; plots: {', '.join(p.name for p in res.plots) or 'none'}")
    if res.n_failed:
        typer.echo("re-run the same command to retry the failed jobs (completed ones are skipped)")
        raise typer.Exit(code=1)


@app.command("stereo")
def stereo_command(
    left: Annotated[Path, typer.Argument(help="Left rectified greyscale image (PNG).")],
    right: Annotated[Path, typer.Argument(help="Right rectified greyscale image (PNG).")],
    num_disparities: Annotated[int, typer.Option("--num-disparities", help="Search range, multiple of 16.")] = 64,
    out: Annotated[Path, typer.Option("--out", help="Output .npy (float32, NaN = no match).")] = Path("disparity.npy"),
    window_px: Annotated[int, typer.Option("--window", help="SAD window side (odd).")] = 9,
) -> None:
    """MER SAD stereo on any rectified greyscale pair; writes float32 disparity."""
    preflight("stereo", files={"--out": out})
    from rover_sim.cli.stereo import stereo_cmd

    try:
        stereo_cmd(left, right, num_disparities, out, window_px)
    except RoverSimError as e:
        bad_input(e)


app.command("export")(export_cmd)
app.command("orbital")(orbital_cmd)
bench_app.command("globalloc")(bench_globalloc_cmd)


def main() -> None:  # pragma: no cover - console entry point
    from rover_sim.interrupts import install_sigterm_handler

    install_sigterm_handler()  # SIGTERM stops a run like Ctrl-C (exit 143); commands also install it themselves
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
