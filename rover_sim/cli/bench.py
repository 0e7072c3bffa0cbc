"""``rover-sim bench ...``: one command per benchmark (:mod:`rover_sim.bench`); each prints a markdown table and can
write JSON and JUnit XML."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rover_sim.cli.options import IMPL_HELP, JsonOpt, JunitOpt, PlannerOpt, StereoOpt, VoOpt, bad_input
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
        list[str] | None, typer.Option("--stereo", help=f"Also run this stereo matcher ({IMPL_HELP}); repeatable.")
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
    junit: JunitOpt = None,
) -> None:
    """VO cases: MSSTB rock course, 30 m slope, featureless soil, rover shadow, flat benign ground; MER VO beside
    any --vo plugins. Each case runs on the flight sensor profile, and (unless --quick) again on the ideal profile
    and with the full-pose VO update; the tables say which."""
    from rover_sim.bench.missions import VO_CASES

    for c in case or []:
        if c not in VO_CASES:
            bad_input(ValueError(f"--case {c!r}: choose from {', '.join(VO_CASES)}"))
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
        bad_input(ValueError("--update-baseline outside a source checkout needs --baseline PATH (the file to write)"))
    for p in profile or []:
        if p not in ("flight", "ideal"):
            bad_input(ValueError(f"--profile {p!r}: choose flight or ideal"))
    path = str(json) if json else None
    with guarded():
        from rover_sim.bench.junit_cases import suite_cases
        from rover_sim.bench.missions import bench_suite
        from rover_sim.scenario.loading import plugin_overrides

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
