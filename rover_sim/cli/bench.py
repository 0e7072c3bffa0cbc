"""``rover-sim bench ...``: one command per benchmark (:mod:`rover_sim.bench`); each prints a markdown table and can
write JSON and JUnit XML."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rover_sim.cli.options import IMPL_HELP, JsonOpt, JunitOpt, PlannerOpt, StereoOpt, VoOpt, bad_input
from rover_sim.cli.preflight import preflight
from rover_sim.cli.status import finish, guarded

bench_app = typer.Typer(help="Benchmarks: print a markdown table, optionally write JSON.", no_args_is_help=True)

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
        bad_input(ValueError(f"--soil-model must be 'bekker' or 'wong_reece', not {soil_model!r}"))
    preflight("bench slip", junit, files={"--json": json, "--png": png if soil_model == "wong_reece" else None})
    with guarded(junit, "bench slip"):
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


@bench_app.command("render")
def bench_render_cmd(json: JsonOpt = None, junit: JunitOpt = None) -> None:
    """Render timings: 256x256 stereo pair and 1024x1024 image, with and without shadows."""
    preflight("bench render", junit, files={"--json": json})
    with guarded(junit, "bench render"):
        from rover_sim.bench.junit_cases import render_cases
        from rover_sim.bench.render import bench_render

        result = bench_render(str(json) if json else None)
    finish(junit, "bench render", render_cases(result))


@bench_app.command("stereo")
def bench_stereo_cmd(
    json: JsonOpt = None,
    stereo: Annotated[
        list[str] | None, typer.Option("--stereo", help=f"Also run this stereo matcher ({IMPL_HELP}); repeatable.")
    ] = None,
    junit: JunitOpt = None,
    profile: Annotated[str, typer.Option("--profile", help="Pairs: flight (and ideal beside it) | ideal.")] = "flight",
) -> None:
    """MER SAD stereo vs OpenCV StereoBM on rendered hazcam pairs with ground truth (speed, density, bad-1px) at
    256x256 and 1024x1024; any --stereo plugin on the same 256 px pairs."""
    preflight("bench stereo", junit, files={"--json": json}, plugins={"stereo": stereo})
    with guarded(junit, "bench stereo"):
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
    preflight("bench autonav", junit, files={"--json": json}, plugins={"vo": vo, "stereo": stereo, "planner": planner})
    with guarded(junit, "bench autonav"):
        from rover_sim.bench.autonav import bench_autonav
        from rover_sim.bench.junit_cases import autonav_cases
        from rover_sim.scenario.loading import plugin_overrides

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
    """Sol-scale and 1 km drives on streamed terrain: distance, wall time, real-time factor, peak and
    100 m RSS, recording size, DR/VO errors, goal distance; each case in a fresh process."""
    preflight("bench traverse", junit, files={"--json": json}, dirs={"--out": out})
    with guarded(junit, "bench traverse"):
        from rover_sim.bench.junit_cases import traverse_cases
        from rover_sim.bench.traverse import bench_traverse

        r = bench_traverse(str(json) if json else None, str(out), case or None, tuple(set_ or ()))
    finish(junit, "bench traverse", traverse_cases(r))


@bench_app.command("dimes")
def bench_dimes_cmd(
    json: JsonOpt = None, runs: Annotated[int, typer.Option(help="Seeded descents.")] = 50, junit: JunitOpt = None
) -> None:
    """DIMES: Monte-Carlo descents over winds and terrains; horizontal velocity error and featureless rejection."""
    preflight("bench dimes", junit, files={"--json": json})
    with guarded(junit, "bench dimes"):
        from rover_sim.bench.dimes import bench_dimes
        from rover_sim.bench.junit_cases import dimes_cases

        result = bench_dimes(str(json) if json else None, runs=runs)
    finish(junit, "bench dimes", dimes_cases(result))


@bench_app.command("sweep")
def bench_sweep_cmd(json: JsonOpt = None, junit: JunitOpt = None) -> None:
    """Sweep speed: 8 short jobs serially and on a 2-worker pool (acceptance: parallel <= 0.65x serial)."""
    preflight("bench sweep", junit, files={"--json": json})
    with guarded(junit, "bench sweep"):
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
    preflight("bench rocks", junit, files={"--json": json})
    with guarded(junit, "bench rocks"):
        from rover_sim.bench.junit_cases import rocks_cases
        from rover_sim.bench.rocks import bench_rocks

        result = bench_rocks(
            str(json) if json else None, seed=seed, irregular_fraction=irregular_fraction, profile=profile
        )
    finish(junit, "bench rocks", rocks_cases(result))


SeedsOpt = Annotated[
    str | None,
    typer.Option("--seeds", help="A count N (the first N of the command's seed set), a range A-B or a list A,B,C."),
]
PerturbOpt = Annotated[
    str | None,
    typer.Option(
        "--perturb",
        help="EPS[:SEED]: add a seeded perturbation of EPS metres and radians to each run's settled initial state "
        "(what another CPU or build does to a chaotic drive).",
    ),
]
WorkersOpt = Annotated[
    int | None, typer.Option("--workers", min=0, help="Local worker processes (0: in this process) [default: CPUs].")
]
SchedulerOpt = Annotated[
    str | None, typer.Option("--scheduler", help="Run the jobs on this Dask scheduler (tcp://host:port) instead.")
]


@bench_app.command("report")
def bench_report_cmd(
    path: Annotated[Path, typer.Argument(help="A `bench suite --json` or `bench vo --json` file.")],
) -> None:
    """Print a benchmark JSON as markdown tables (median [90 % CI] per figure), with seeds, profile, cell size and
    machine: the docs' benchmark pages are made this way from committed JSON."""
    import json as _json

    from rover_sim.bench.report import markdown

    try:
        data = _json.loads(path.read_text())
        typer.echo(markdown(data))
    except (OSError, ValueError, KeyError, TypeError) as e:
        bad_input(ValueError(f"{path}: not a bench suite/vo JSON ({type(e).__name__}: {e})"))


@bench_app.command("vo")
def bench_vo_cmd(
    json: JsonOpt = None,
    vo: Annotated[
        list[str] | None, typer.Option("--vo", help=f"Also run this visual odometer ({IMPL_HELP}); repeatable.")
    ] = None,
    case: Annotated[list[str] | None, typer.Option("--case", help="Only these cases (repeatable).")] = None,
    quick: Annotated[
        bool, typer.Option("--quick", help="Flight profile only: skip the ideal-profile and full-pose VO reruns.")
    ] = False,
    seeds: SeedsOpt = None,
    perturb: PerturbOpt = None,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    junit: JunitOpt = None,
) -> None:
    """VO cases over seeds: MSSTB rock course, 30 m slope, featureless soil, rover shadow, flat benign ground; MER VO
    beside any --vo plugins on the same seeds (default: the first 8 of the published set). Each case runs on the
    flight sensor profile, and (unless --quick) again on the ideal profile and with the full-pose VO update; every
    cell is a median [90 % CI] over the seeds."""
    from rover_sim.bench.vo import VO_CASES

    for c in case or []:
        if c not in VO_CASES:
            bad_input(ValueError(f"--case {c!r}: choose from {', '.join(VO_CASES)}"))
    preflight("bench vo", junit, files={"--json": json}, plugins={"vo": vo})
    with guarded(junit, "bench vo"):
        from rover_sim.bench.seeded import parse_perturb
        from rover_sim.bench.seeds import parse_seeds
        from rover_sim.bench.suite import PUBLISHED_SEEDS, interrupt_of
        from rover_sim.bench.vo import bench_vo, junit_cases

        chosen = parse_seeds(seeds, "published", PUBLISHED_SEEDS)
        stacks, _ = bench_vo(str(json) if json else None, chosen, plugins=vo or None, cases=case or None,
                             quick=quick, perturb=parse_perturb(perturb), workers=workers,
                             scheduler=scheduler)  # fmt: skip
        cases = junit_cases(stacks)
        stop = interrupt_of(stacks)
        if stop is not None:
            from rover_sim.io.junit import write_junit

            write_junit(junit, "bench vo", cases)
            raise stop
    finish(junit, "bench vo", cases)


@bench_app.command("suite")
def bench_suite_cmd(
    json: JsonOpt = None,
    fast: Annotated[
        bool, typer.Option("--fast", help="The CI gate: scenarios with fast = true, on the gate seeds, flight profile.")
    ] = False,
    seeds: SeedsOpt = None,
    update_baseline: Annotated[
        bool,
        typer.Option(
            "--update-baseline", help="Record these seeds as the baseline (plus a perturbed run for the spread)."
        ),
    ] = False,
    baseline: Annotated[
        Path | None,
        typer.Option("--baseline", help="Gate against this baseline file (yours) instead of the committed one."),
    ] = None,
    vo: VoOpt = None,
    stereo: StereoOpt = None,
    planner: PlannerOpt = None,
    replay_vo: Annotated[
        list[str] | None,
        typer.Option(
            "--replay-vo",
            help=f"Also run this visual odometer ({IMPL_HELP}) on the built-in stack's identical inputs (open loop, "
            "paired: every seed's images and IMU); reported and gated in the JSON, not in the exit status. "
            "Repeatable.",
        ),
    ] = None,
    perturb: PerturbOpt = None,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    png: Annotated[Path | None, typer.Option("--png", help="With a plugin: the scorecard's box plots.")] = None,
    scenario: Annotated[
        list[str] | None, typer.Option("--scenario", help="Only this scenario (repeatable) [default: all].")
    ] = None,
    junit: JunitOpt = None,
    profile: Annotated[
        list[str] | None,
        typer.Option(
            "--profile", help="Sensor profile(s) to run, flight or ideal (repeatable) [default: both; --fast: flight]."
        ),
    ] = None,
) -> None:
    """Run the scenario catalogue over seeds: per scenario the median [90 % CI] of each figure and its verdict over
    the seeds (the scenario's pass criteria per run, its pass rate and its bounds on medians and percentiles).

    --fast is the CI gate: the fast scenarios on the gate seeds, compared seed by seed with the baseline (paired
    exact signed-rank tests, Holm family-wise 1 %, effect-size floors; the minimum detectable change is printed).
    With --vo/--stereo/--planner the same seeds run with those parts swapped in, side by side with the built-in
    stack (a scorecard; --png draws its box plots). Exit status: 0 all scenarios hold, 1 a scenario failed or
    regressed, 2 bad input, 130/143 interrupted."""
    from rover_sim.resources import source_checkout

    if update_baseline and baseline is None and source_checkout() is None:
        bad_input(ValueError("--update-baseline outside a source checkout needs --baseline PATH (the file to write)"))
    for p in profile or []:
        if p not in ("flight", "ideal"):
            bad_input(ValueError(f"--profile {p!r}: choose flight or ideal"))
    plugin_json = Path(json).with_suffix(".plugins.json") if json and (vo or stereo or planner) else None
    files = {"--json": json, "--json (plugin rows)": plugin_json, "--png": png,
             "--baseline": baseline if update_baseline else None}  # fmt: skip
    preflight(
        "bench suite",
        junit,
        files=files,
        plugins={
            "vo": [*([vo] if isinstance(vo, str) else vo or []), *(replay_vo or [])],
            "stereo": stereo,
            "planner": planner,
        },
    )
    with guarded(junit, "bench suite"):
        from rover_sim.bench.seeded import parse_perturb
        from rover_sim.bench.seeds import parse_seeds
        from rover_sim.bench.suite import GATE_SEEDS, PUBLISHED_SEEDS, bench_suite, interrupt_of, junit_cases
        from rover_sim.scenario.loading import plugin_overrides

        chosen = parse_seeds(seeds, "gate" if fast else "published", GATE_SEEDS if fast else PUBLISHED_SEEDS)
        sets = plugin_overrides(vo, stereo, planner)
        plugins = {", ".join(x for x in (vo, stereo, planner) if x): sets} if sets else None
        result = bench_suite(str(json) if json else None, chosen, fast=fast, profiles=tuple(profile or ()) or None,
                             plugins=plugins, replay={v: v for v in replay_vo or []} or None,
                             baseline_path=baseline, update_baseline=update_baseline,
                             perturb=parse_perturb(perturb), workers=workers, scheduler=scheduler,
                             png_path=png, only=tuple(scenario or ()))  # fmt: skip
        cases = junit_cases(result.stacks)
        stop = interrupt_of(result.stacks)
        if stop is not None:
            from rover_sim.io.junit import write_junit

            write_junit(junit, "bench suite", cases)
            raise stop
    finish(junit, "bench suite", cases)
