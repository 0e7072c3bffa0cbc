"""`rover-sim` command line: a thin layer over library functions (evo/kiss-icp style)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

import rover_sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported anywhere)
from rover_sim.cli.export import export_cmd
from rover_sim.cli.status import finish, guarded
from rover_sim.cli.view import view_cmd
from rover_sim.errors import RoverSimError

app = typer.Typer(help="MER-class rover simulator with a MER-style navigation stack.", no_args_is_help=True)
bench_app = typer.Typer(help="Benchmarks: print a markdown table, optionally write JSON.", no_args_is_help=True)
app.add_typer(bench_app, name="bench")
app.command("view")(view_cmd)

JsonOpt = Annotated[Path | None, typer.Option("--json", help="Write the results as JSON to this path.")]
_IMPL = "an import path 'pkg.module:Class' or an entry point in 'rover_sim.plugins'"
VoOpt = Annotated[str | None, typer.Option("--vo", help=f"Visual odometer: {_IMPL} (nav.protocols.VisualOdometer).")]
StereoOpt = Annotated[
    str | None, typer.Option("--stereo", help=f"Stereo matcher: {_IMPL} (nav.protocols.StereoMatcher).")
]
PlannerOpt = Annotated[str | None, typer.Option("--planner", help=f"Planner: {_IMPL} (nav.protocols.Planner).")]
JunitOpt = Annotated[
    Path | None, typer.Option("--junit", help="Write JUnit XML (one test case per scenario/case) to this path.")
]


RENDER_PX = (16, 2048)  # `render --resolution`: MuJoCo's offscreen buffer is allocated at this size


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


SoilModelOpt = Annotated[
    str,
    typer.Option(
        "--soil-model",
        help="wong_reece (default: the mobility benchmark of the default law, deformable terrain; writes --png) or "
        "bekker (the slip table of the earlier patch law).",
    ),
]


@bench_app.command("slip")
def bench_slip(
    json: JsonOpt = None,
    seed: int = 0,
    junit: JunitOpt = None,
    soil_model: SoilModelOpt = "wong_reece",
    png: Annotated[str, typer.Option(help="wong_reece only: PNG of DP/W vs slip and slip vs slope.")] = (
        "runs/bench_slip.png"
    ),
) -> None:
    """Drive straight uphill on uniform sand and bedrock at 0-30 deg; slip vs published anchors, physics speed."""
    if soil_model not in ("bekker", "wong_reece"):
        _fail(ValueError(f"--soil-model must be 'bekker' or 'wong_reece', not {soil_model!r}"))
    with guarded():
        if soil_model == "wong_reece":
            from rover_sim.bench import mobility
            from rover_sim.bench.junit_cases import mobility_cases

            result = mobility.run(str(json) if json else None, seed=seed, png_path=png)
            cases = mobility_cases(result)
        else:
            from rover_sim.bench import slip
            from rover_sim.bench.junit_cases import slip_cases

            result = slip.run(str(json) if json else None, seed=seed)
            cases = slip_cases(result)
    finish(junit, "bench slip", cases)


@bench_app.command("wheel")
def bench_wheel_cmd(
    json: JsonOpt = None,
    data: Annotated[
        Path | None,
        typer.Option("--data", help="CSV of single-wheel tests: columns wheel, slip_angle_deg, slip, load_N "
                     "(drawbar_pull_N, lateral_force_N, sinkage_mm scored when present) [default: the CMU tests]."),
    ] = None,
    wheel: Annotated[
        str | None, typer.Option("--wheel", help="Geometry of every row: grouser | smooth | mer (default: the wheel "
                                 "column, or radius_m / width_m / grouser_height_m columns).")
    ] = None,
    png: Annotated[str, typer.Option(help="PNG grid: measured vs the rig per slip angle and quantity.")] = (
        "runs/bench_wheel.png"
    ),
    junit: JunitOpt = None,
) -> None:
    """Single-wheel rig on the rover's wheel-soil law (soil bin, deformable heightfield) against measured tests:
    RMSE of drawbar pull, lateral force and sinkage per wheel and slip-angle band; drawbar pull monotone at 0 deg."""
    with guarded():
        from rover_sim.bench.junit_cases import wheel_cases
        from rover_sim.bench.wheel import bench_wheel

        result = bench_wheel(data, str(json) if json else None, wheel=wheel, png_path=png)
    finish(junit, "bench wheel", wheel_cases(result))


@bench_app.command("render")
def bench_render_cmd(json: JsonOpt = None, junit: JunitOpt = None) -> None:
    """Render timings: 256x256 stereo pair and 1024x1024 image, with and without shadows."""
    with guarded():
        from rover_sim.bench.junit_cases import render_cases
        from rover_sim.bench.render import bench_render

        result = bench_render(str(json) if json else None)
    finish(junit, "bench render", render_cases(result))


@bench_app.command("stereo")
def bench_stereo_cmd(
    json: JsonOpt = None,
    stereo: Annotated[
        list[str] | None, typer.Option("--stereo", help=f"Also run this stereo matcher ({_IMPL}); repeatable.")
    ] = None,
    junit: JunitOpt = None,
    profile: Annotated[str, typer.Option("--profile", help="Pairs: flight (and ideal beside it) | ideal.")] = "flight",
) -> None:
    """MER SAD stereo vs OpenCV StereoBM on rendered hazcam pairs with ground truth (speed, density, bad-1px) at
    256x256 and 1024x1024; any --stereo plugin on the same 256 px pairs."""
    with guarded():
        from rover_sim.bench.junit_cases import stereo_cases
        from rover_sim.bench.stereo import bench_stereo

        r = bench_stereo(str(json) if json else None, plugins=stereo or None, profile=profile)
    finish(junit, "bench stereo", stereo_cases(r))


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
    junit: JunitOpt = None,
) -> None:
    """GESTALT autonav over seeded rock fields (10 % cover, rocks to 60 cm, goal 20 m away); with --planner,
    --stereo or --vo the same fields run again with those parts swapped in."""
    path = str(json) if json else None
    with guarded():
        from rover_sim.bench.autonav import bench_autonav
        from rover_sim.bench.junit_cases import autonav_cases
        from rover_sim.mission.scenario import plugin_overrides

        r = bench_autonav(path, runs=runs, first_seed=first_seed, workers=workers, seeds=seed)
        cases = autonav_cases(r)
        overrides = plugin_overrides(vo, stereo, planner)
        if overrides and not any(c.error for c in cases):
            label = ", ".join(x for x in (vo, stereo, planner) if x)
            plugin_path = str(Path(path).with_suffix(".plugins.json")) if path else None
            rp = bench_autonav(plugin_path, runs=runs, first_seed=first_seed, workers=workers, seeds=seed,
                               overrides=tuple(overrides), label=label)  # fmt: skip
            cases += autonav_cases(rp)
    finish(junit, "bench autonav", cases)


@bench_app.command("traverse")
def bench_traverse_cmd(
    json: JsonOpt = None,
    case: Annotated[list[str] | None, typer.Option(help="Run only these cases (repeatable).")] = None,
    out: Annotated[Path, typer.Option(help="Where each case writes its outputs and recording.")] = Path(
        "runs/bench_traverse"
    ),
    set_: Annotated[list[str] | None, typer.Option("--set", help="Override a field of every case.")] = None,
    junit: JunitOpt = None,
) -> None:
    """Sol-scale and 1 km drives on streamed terrain (issue #18): distance, wall time, real-time factor, peak and
    100 m RSS, recording size, DR/VO errors, goal distance; each case in a fresh process."""
    with guarded():
        from rover_sim.bench.junit_cases import traverse_cases
        from rover_sim.bench.traverse import bench_traverse

        r = bench_traverse(str(json) if json else None, str(out), case or None, tuple(set_ or ()))
    finish(junit, "bench traverse", traverse_cases(r))


@bench_app.command("dimes")
def bench_dimes_cmd(
    json: JsonOpt = None, runs: Annotated[int, typer.Option(help="Seeded descents.")] = 50, junit: JunitOpt = None
) -> None:
    """DIMES: Monte-Carlo descents over winds and terrains; horizontal velocity error and featureless rejection."""
    with guarded():
        from rover_sim.bench.dimes import bench_dimes
        from rover_sim.bench.junit_cases import dimes_cases

        result = bench_dimes(str(json) if json else None, runs=runs)
    finish(junit, "bench dimes", dimes_cases(result))


@bench_app.command("sweep")
def bench_sweep_cmd(json: JsonOpt = None, junit: JunitOpt = None) -> None:
    """Sweep speed: 8 short jobs serially and on a 2-worker pool (acceptance: parallel <= 0.65x serial)."""
    with guarded():
        from rover_sim.bench.junit_cases import sweep_cases
        from rover_sim.bench.sweep import bench_sweep

        result = bench_sweep(str(json) if json else None)
    finish(junit, "bench sweep", sweep_cases(result))


@bench_app.command("rocks")
def bench_rocks_cmd(
    json: JsonOpt = None,
    seed: Annotated[int | None, typer.Option(help="Replace the scenario seed (another rock field).")] = None,
    junit: JunitOpt = None,
    irregular_fraction: Annotated[
        float | None,
        typer.Option("--irregular-fraction", min=0.0, max=1.0, help="Fraction of irregular rocks (0..1)."),
    ] = None,
    profile: Annotated[
        str | None, typer.Option("--profile", help="Sensor profile: flight | ideal (default: the scenario's).")
    ] = None,
) -> None:
    """Rock-based localisation: extraction, modelling, matching between sites, chain adjustment vs DR and VO;
    figures by rock class (analytic / irregular) with --irregular-fraction."""
    with guarded():
        from rover_sim.bench.junit_cases import rocks_cases
        from rover_sim.bench.rocks import bench_rocks

        result = bench_rocks(
            str(json) if json else None, seed=seed, irregular_fraction=irregular_fraction, profile=profile
        )
    finish(junit, "bench rocks", rocks_cases(result))


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
    from rover_sim.mission.scenario import load_scenario
    from rover_sim.sim.world import Sun

    pairs = ("navcam", *HAZCAM_PAIRS)
    if pair not in pairs:
        _fail(ValueError(f"--pair {pair!r}: choose from {', '.join(pairs)}"))
    if not RENDER_PX[0] <= resolution <= RENDER_PX[1]:  # checked first: too large an offscreen buffer kills MuJoCo
        _fail(ValueError(f"--resolution {resolution}: allowed {RENDER_PX[0]}..{RENDER_PX[1]} pixels"))
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
    quick: Annotated[
        bool, typer.Option("--quick", help="Flight profile only: skip the ideal-profile and full-pose VO reruns.")
    ] = False,
    junit: JunitOpt = None,
) -> None:
    """VO cases: MSSTB rock course, 30 m slope, featureless soil, rover shadow, flat benign ground; MER VO beside
    any --vo plugins. Each case runs on the flight sensor profile, and (unless --quick) again on the ideal profile
    and with the full-pose VO update; the tables say which."""
    from rover_sim.bench.missions import VO_CASES

    for c in case or []:
        if c not in VO_CASES:
            _fail(ValueError(f"--case {c!r}: choose from {', '.join(VO_CASES)}"))
    with guarded():
        from rover_sim.bench.junit_cases import vo_cases
        from rover_sim.bench.missions import bench_vo

        results = bench_vo(str(json) if json else None, plugins=vo or None, cases=case or None, quick=quick)
    finish(junit, "bench vo", vo_cases(results))


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
    junit: JunitOpt = None,
    baseline: Annotated[
        Path | None,
        typer.Option("--baseline", help="Compare with this baseline file (yours; relative tolerances) instead."),
    ] = None,
    tolerance: Annotated[
        float, typer.Option("--tolerance", min=0.0, max=10.0, help="Relative tolerance for --baseline.")
    ] = 0.10,
    profile: Annotated[
        list[str] | None,
        typer.Option(
            "--profile",
            help="Sensor profile(s) to run, flight or ideal (repeatable); default both, with --fast only the "
            "profile the baseline was recorded on.",
        ),
    ] = None,
) -> None:
    """Run the scenario catalogue; exit 1 if a scenario fails its criterion or regresses past the baseline.

    Sensor profiles: each scenario runs on the flight and the ideal profile (--fast: only the baseline's profile,
    the CI gate); the baseline gates the run on the profile it was recorded on.

    With --vo/--stereo/--planner the catalogue runs a second time with those parts swapped in, and both tables
    print (the plugin stack is judged by each scenario's criteria; the baseline gates the built-in stack).
    --baseline FILE compares every stack with your own file instead (a metric may get --tolerance worse, relative;
    FILE: a bench suite --json, or what --update-baseline writes there)."""
    from rover_sim.resources import source_checkout

    if update_baseline and baseline is None and source_checkout() is None:
        _fail(ValueError("--update-baseline outside a source checkout needs --baseline PATH (the file to write)"))
    for p in profile or []:
        if p not in ("flight", "ideal"):
            _fail(ValueError(f"--profile {p!r}: choose flight or ideal"))
    path = str(json) if json else None
    with guarded():
        from rover_sim.bench.junit_cases import suite_cases
        from rover_sim.bench.missions import bench_suite
        from rover_sim.mission.scenario import plugin_overrides

        profiles = tuple(profile) if profile else None
        kw = {"fast": fast, "baseline_path": baseline, "tolerance": tolerance, "profiles": profiles}
        rows, _ = bench_suite(path, update_baseline=update_baseline, **kw)
        cases = suite_cases(rows)
        overrides = plugin_overrides(vo, stereo, planner)
        if overrides and not any(c.error for c in cases):
            label = ", ".join(x for x in (vo, stereo, planner) if x)
            plugin_path = str(Path(path).with_suffix(".plugins.json")) if path else None
            plugin_rows, _ = bench_suite(plugin_path, overrides=overrides, label=label, **kw)
            cases += suite_cases(plugin_rows, label)
    finish(junit, "bench suite", cases)


SetOpt = Annotated[list[str] | None, typer.Option("--set", help="Override a scenario field: dotted.key=value.")]


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
    with guarded():
        from rover_sim.mission.run import run_scenario
        from rover_sim.mission.scenario import load_scenario, plugin_overrides

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


@app.command("scenarios")
def scenarios_cmd() -> None:
    """List the scenario catalogue: name, `fast` (in the CI subset) and the first line of the description."""
    from rover_sim.mission.scenario import catalogue, load_scenario

    names = catalogue()
    if not names:
        from rover_sim.resources import scenarios_dir

        _fail(FileNotFoundError(f"no scenario files (*.toml) in {scenarios_dir()}"))
    width = max((len(n) for n in names), default=0)
    bad = False
    for name in names:
        try:
            s = load_scenario(name)
        except RoverSimError as e:
            typer.echo(f"{name:<{width}}  ?     invalid: {e}")
            bad = True
            continue
        first = next(iter(s.description.strip().splitlines()), "")
        typer.echo(f"{name:<{width}}  {'fast' if s.fast else '-   '}  {first}")
    if bad:
        raise typer.Exit(code=2)


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


app.command("export")(export_cmd)


def main() -> None:  # pragma: no cover - console entry point
    from rover_sim.interrupts import install_sigterm_handler

    install_sigterm_handler()  # SIGTERM stops a run like Ctrl-C (exit 143); commands also install it themselves
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
