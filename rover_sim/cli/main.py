"""`rover-sim` command line: a thin layer over library functions (evo/kiss-icp style)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

import rover_sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported anywhere)
from rover_sim.errors import RoverSimError

app = typer.Typer(help="MER-class rover simulator with a MER-style navigation stack.", no_args_is_help=True)
bench_app = typer.Typer(help="Benchmarks: print a markdown table, optionally write JSON.", no_args_is_help=True)
app.add_typer(bench_app, name="bench")

JsonOpt = Annotated[Path | None, typer.Option("--json", help="Write the results as JSON to this path.")]
_IMPL = "an import path 'pkg.module:Class' or an entry point in 'rover_sim.plugins'"
VoOpt = Annotated[str | None, typer.Option("--vo", help=f"Visual odometer: {_IMPL} (nav.protocols.VisualOdometer).")]
StereoOpt = Annotated[
    str | None, typer.Option("--stereo", help=f"Stereo matcher: {_IMPL} (nav.protocols.StereoMatcher).")
]
PlannerOpt = Annotated[str | None, typer.Option("--planner", help=f"Planner: {_IMPL} (nav.protocols.Planner).")]


def _fail(err: Exception) -> None:
    typer.secho(f"error: {err}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code=2)


@app.command("check-gl")
def check_gl_cmd() -> None:
    """Check that offscreen rendering (EGL) works; prints the install hint if it does not."""
    from rover_sim.render.renderer import check_gl

    try:
        check_gl()
    except RoverSimError as e:
        _fail(e)
    typer.echo("offscreen rendering OK (MUJOCO_GL=egl)")


@bench_app.command("slip")
def bench_slip(json: JsonOpt = None, seed: int = 0, png: str = "runs/bench_slip.png") -> None:
    """The mobility benchmark: uphill slip vs the MER anchors, held-out checks (speed, parked, cross-slope, locked
    wheel, ruts), physics speed with the deformable terrain; JSON and a PNG (DP/W vs slip, slip vs slope)."""
    from rover_sim.bench import mobility as slip

    result = slip.run(str(json) if json else None, seed=seed, png_path=png)
    if not result["all_pass"]:
        raise typer.Exit(code=1)


@bench_app.command("render")
def bench_render_cmd(json: JsonOpt = None) -> None:
    """Render timings: 256x256 stereo pair and 1024x1024 image, with and without shadows."""
    from rover_sim.bench.render import bench_render
    from rover_sim.mission import acceptance

    result = bench_render(str(json) if json else None)
    if result["stereo_pair_256_shadows_ms"] > acceptance.RENDER.max_pair_256_shadows_ms:
        raise typer.Exit(code=1)


@bench_app.command("stereo")
def bench_stereo_cmd(
    json: JsonOpt = None,
    stereo: Annotated[
        list[str] | None, typer.Option("--stereo", help=f"Also run this stereo matcher ({_IMPL}); repeatable.")
    ] = None,
) -> None:
    """MER SAD stereo vs OpenCV StereoBM on rendered hazcam pairs with ground truth (speed, density, bad-1px);
    any --stereo plugin on the same pairs."""
    from rover_sim.bench.stereo import bench_stereo

    try:
        r = bench_stereo(str(json) if json else None, plugins=stereo or None)
    except RoverSimError as e:
        _fail(e)
    if not r["passed"]:
        raise typer.Exit(code=1)


@bench_app.command("autonav")
def bench_autonav_cmd(
    json: JsonOpt = None,
    runs: Annotated[int, typer.Option(help="Number of seeded rock fields.")] = 20,
    first_seed: Annotated[int, typer.Option(help="Seed of the first field.")] = 0,
    seed: Annotated[list[int] | None, typer.Option(help="Run only these seeds (repeatable).")] = None,
    workers: Annotated[int, typer.Option(help="Fields run at once (spawn pool; cycle times then share cores).")] = 1,
    stereo: StereoOpt = None,
    planner: PlannerOpt = None,
    vo: VoOpt = None,
) -> None:
    """GESTALT autonav over seeded rock fields (10 % cover, rocks to 60 cm, goal 20 m away); with --planner,
    --stereo or --vo the same fields run again with those parts swapped in."""
    from rover_sim.bench.autonav import bench_autonav
    from rover_sim.mission.scenario import plugin_overrides

    path = str(json) if json else None
    try:
        r = bench_autonav(path, runs=runs, first_seed=first_seed, workers=workers, seeds=seed)
        ok = r["passed"]
        overrides = plugin_overrides(vo, stereo, planner)
        if overrides:
            label = ", ".join(x for x in (vo, stereo, planner) if x)
            plugin_path = str(Path(path).with_suffix(".plugins.json")) if path else None
            rp = bench_autonav(plugin_path, runs=runs, first_seed=first_seed, workers=workers, seeds=seed,
                               overrides=tuple(overrides), label=label)  # fmt: skip
            ok &= rp["passed"]
    except RoverSimError as e:
        _fail(e)
    if not ok:
        raise typer.Exit(code=1)


@bench_app.command("dimes")
def bench_dimes_cmd(json: JsonOpt = None, runs: Annotated[int, typer.Option(help="Seeded descents.")] = 50) -> None:
    """DIMES: Monte-Carlo descents over winds and terrains; horizontal velocity error and featureless rejection."""
    from rover_sim.bench.dimes import bench_dimes

    if not bench_dimes(str(json) if json else None, runs=runs)["passed"]:
        raise typer.Exit(code=1)


@bench_app.command("sweep")
def bench_sweep_cmd(json: JsonOpt = None) -> None:
    """Sweep speed: 8 short jobs serially and on a 2-worker pool (acceptance: parallel <= 0.65x serial)."""
    from rover_sim.bench.sweep import bench_sweep

    if not bench_sweep(str(json) if json else None)["passed"]:
        raise typer.Exit(code=1)


@bench_app.command("rocks")
def bench_rocks_cmd(
    json: JsonOpt = None,
    seed: Annotated[int | None, typer.Option(help="Replace the scenario seed (another rock field).")] = None,
) -> None:
    """Rock-based localisation: extraction, modelling, matching between sites, chain adjustment vs DR and VO."""
    from rover_sim.bench.rocks import bench_rocks, passes

    if not passes(bench_rocks(str(json) if json else None, seed=seed)):
        raise typer.Exit(code=1)


@app.command("render")
def render_cmd(
    scenario: Annotated[str, typer.Argument(help="Scenario whose terrain, sun and start pose to use.")],
    out: Annotated[Path, typer.Option("--out")] = Path("runs/render"),
    pair: Annotated[str, typer.Option(help="navcam | hazcam_front | hazcam_rear")] = "navcam",
    resolution: Annotated[int, typer.Option(help="Image side in pixels.")] = 256,
    seed: Annotated[int | None, typer.Option()] = None,
) -> None:
    """Write a stereo pair, its depth and the camera-model JSON at the scenario's start pose."""
    import math

    from rover_sim.bench.render import render_to_dir
    from rover_sim.mission.scenario import load_scenario
    from rover_sim.sim.world import Sun

    try:
        sc = load_scenario(scenario, seed=seed)
    except RoverSimError as e:
        _fail(e)
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


@bench_app.command("vo")
def bench_vo_cmd(
    json: JsonOpt = None,
    vo: Annotated[
        list[str] | None, typer.Option("--vo", help=f"Also run this visual odometer ({_IMPL}); repeatable.")
    ] = None,
    case: Annotated[list[str] | None, typer.Option("--case", help="Only these cases (repeatable).")] = None,
) -> None:
    """VO cases: MSSTB rock course, 30 m slope, featureless soil, rover shadow; MER VO beside any --vo plugins."""
    from rover_sim.bench.missions import VO_CASES, all_passed, bench_vo

    for c in case or []:
        if c not in VO_CASES:
            _fail(ValueError(f"--case {c!r}: choose from {', '.join(VO_CASES)}"))
    try:
        results = bench_vo(str(json) if json else None, plugins=vo or None, cases=case or None)
    except RoverSimError as e:
        _fail(e)
    if not all_passed(results):
        raise typer.Exit(code=1)


@bench_app.command("suite")
def bench_suite_cmd(
    json: JsonOpt = None,
    fast: Annotated[bool, typer.Option("--fast", help="Only the CI subset (scenarios with fast = true).")] = False,
    update_baseline: Annotated[
        bool, typer.Option("--update-baseline", help="Store these results as baseline.")
    ] = False,
    vo: VoOpt = None,
    stereo: StereoOpt = None,
    planner: PlannerOpt = None,
) -> None:
    """Run the scenario catalogue; exit 1 if a scenario fails its criterion or regresses past the baseline.

    With --vo/--stereo/--planner the catalogue runs a second time with those parts swapped in, and both tables
    print (the plugin stack is judged by each scenario's criteria; the baseline gates the built-in stack)."""
    from rover_sim.bench.missions import bench_suite
    from rover_sim.mission.scenario import plugin_overrides

    path = str(json) if json else None
    try:
        _, ok = bench_suite(path, fast=fast, update_baseline=update_baseline)
        overrides = plugin_overrides(vo, stereo, planner)
        if overrides:
            label = ", ".join(x for x in (vo, stereo, planner) if x)
            plugin_path = str(Path(path).with_suffix(".plugins.json")) if path else None
            _, ok_plugin = bench_suite(plugin_path, fast=fast, overrides=overrides, label=label)
            ok &= ok_plugin
    except RoverSimError as e:
        _fail(e)
    if not ok:
        raise typer.Exit(code=1)


SetOpt = Annotated[list[str] | None, typer.Option("--set", help="Override a scenario field: dotted.key=value.")]


@app.command("run")
def run_cmd(
    scenario: Annotated[str, typer.Argument(help="Scenario name (scenarios/<name>.toml) or path to a TOML file.")],
    out: Annotated[Path, typer.Option("--out", help="Output directory.")] = Path("runs/latest"),
    seed: Annotated[int | None, typer.Option("--seed", help="Override the scenario seed.")] = None,
    set_: SetOpt = None,
    record: Annotated[bool, typer.Option("--record/--no-record", help="Write DIR/recording.rrd.")] = True,
    progress: Annotated[bool, typer.Option("--progress/--no-progress")] = True,
    vo: VoOpt = None,
    stereo: StereoOpt = None,
    planner: PlannerOpt = None,
) -> None:
    """Run a mission scenario: writes recording.rrd, metrics.json, trajectories/*.tum, plots/*.png."""
    from rover_sim.mission.run import run_scenario
    from rover_sim.mission.scenario import plugin_overrides

    overrides = plugin_overrides(vo, stereo, planner) + list(set_ or [])
    try:
        metrics = run_scenario(scenario, out, seed=seed, overrides=overrides, record=record, progress=progress)
    except RoverSimError as e:
        _fail(e)
    colour = typer.colors.GREEN if metrics.passed else typer.colors.RED
    typer.secho(f"{metrics.scenario}: {'PASS' if metrics.passed else 'FAIL'} ({metrics.reason})", fg=colour)
    typer.echo(
        f"distance {metrics.distance_m:.2f} m | DR error {metrics.dr_error_pct:.2f} % | VO error "
        f"{metrics.vo_error_pct} % | VO convergence {metrics.vo_convergence_pct} % | max slip {metrics.max_slip_pct} %"
    )
    where = f"outputs in {out}/ (plots in {out}/plots/)"
    typer.echo(f"{where}; open the recording with: rerun {out}/recording.rrd" if record else where)
    if not metrics.passed:
        raise typer.Exit(code=1)


@app.command("demo")
def demo_cmd(out: Annotated[Path, typer.Option("--out")] = Path("runs/demo")) -> None:
    """The main job: the Wopmay scenario with a rerun recording, metrics and plots."""
    run_cmd("wopmay", out=out, seed=None, set_=None, record=True, progress=True)


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
    from rover_sim.mission.sweep import run_sweep

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
        _fail(e)
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
    from rover_sim.cli.stereo import stereo_cmd

    try:
        stereo_cmd(left, right, num_disparities, out, window_px)
    except RoverSimError as e:
        _fail(e)


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
