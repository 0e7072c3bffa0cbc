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


def _fail(err: Exception) -> None:
    typer.secho(f"error: {err}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code=2)


@app.command("check-gl")
def check_gl_cmd() -> None:
    """Check that offscreen rendering (EGL) works; prints the install hint if it does not."""
    from rover_sim.render import check_gl

    try:
        check_gl()
    except RoverSimError as e:
        _fail(e)
    typer.echo("offscreen rendering OK (MUJOCO_GL=egl)")


@bench_app.command("slip")
def bench_slip(json: JsonOpt = None, seed: int = 0) -> None:
    """Drive straight uphill on uniform sand and bedrock at 0-30 deg; slip vs published anchors, physics speed."""
    from rover_sim.bench import slip

    result = slip.run(str(json) if json else None, seed=seed)
    if not result["all_pass"]:
        raise typer.Exit(code=1)


@bench_app.command("vo")
def bench_vo_cmd(json: JsonOpt = None) -> None:
    """VO cases of the issue: MSSTB rock course, 30 m slope, featureless soil, rover shadow."""
    from rover_sim.bench.missions import bench_vo

    results = bench_vo(str(json) if json else None)
    if not all(r["passed"] for r in results.values()):
        raise typer.Exit(code=1)


@bench_app.command("suite")
def bench_suite_cmd(
    json: JsonOpt = None,
    fast: Annotated[bool, typer.Option("--fast", help="Only the CI subset (scenarios with fast = true).")] = False,
    update_baseline: Annotated[bool, typer.Option("--update-baseline", help="Store these results as baseline.")] = False,
) -> None:
    """Run the scenario catalogue; exit 1 if a scenario fails its criterion or regresses past the baseline."""
    from rover_sim.bench.missions import bench_suite

    _, ok = bench_suite(str(json) if json else None, fast=fast, update_baseline=update_baseline)
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
) -> None:
    """Run a mission scenario: writes recording.rrd, metrics.json, trajectories/*.tum, plots/*.png."""
    from rover_sim.runner import run_scenario

    try:
        metrics = run_scenario(scenario, out, seed=seed, overrides=set_ or [], record=record, progress=progress)
    except RoverSimError as e:
        _fail(e)
    colour = typer.colors.GREEN if metrics.passed else typer.colors.RED
    typer.secho(f"{metrics.scenario}: {'PASS' if metrics.passed else 'FAIL'} ({metrics.reason})", fg=colour)
    typer.echo(
        f"distance {metrics.distance_m:.2f} m | DR error {metrics.dr_error_pct:.2f} % | VO error "
        f"{metrics.vo_error_pct} % | VO convergence {metrics.vo_convergence_pct} % | max slip {metrics.max_slip_pct} %"
    )
    typer.echo(f"outputs in {out}/ ; open the recording with: rerun {out}/recording.rrd")
    if not metrics.passed:
        raise typer.Exit(code=1)


@app.command("demo")
def demo_cmd(out: Annotated[Path, typer.Option("--out")] = Path("runs/demo")) -> None:
    """The main job: the Wopmay scenario with a rerun recording, metrics and plots."""
    run_cmd("wopmay", out=out, seed=None, set_=None, record=True, progress=True)


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
