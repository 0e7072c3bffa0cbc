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


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
