"""Options shared by the ``rover-sim`` commands (``--json``, ``--junit``, ``--set``, the plugin options)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

JsonOpt = Annotated[Path | None, typer.Option("--json", help="Write the results as JSON to this path.")]
IMPL_HELP = "an import path 'pkg.module:Class' or an entry point in 'rover_sim.plugins'"
VoOpt = Annotated[
    str | None, typer.Option("--vo", help=f"Visual odometer: {IMPL_HELP} (nav.protocols.VisualOdometer).")
]
StereoOpt = Annotated[
    str | None, typer.Option("--stereo", help=f"Stereo matcher: {IMPL_HELP} (nav.protocols.StereoMatcher).")
]
PlannerOpt = Annotated[str | None, typer.Option("--planner", help=f"Planner: {IMPL_HELP} (nav.protocols.Planner).")]
JunitOpt = Annotated[
    Path | None, typer.Option("--junit", help="Write JUnit XML (one test case per scenario/case) to this path.")
]
SetOpt = Annotated[list[str] | None, typer.Option("--set", help="Override a scenario field: dotted.key=value.")]


def bad_input(err: Exception) -> None:
    """A bad option value or argument: ``error: err`` on stderr and exit status 2."""
    typer.secho(f"error: {err}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code=2)
