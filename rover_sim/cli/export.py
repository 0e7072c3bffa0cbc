"""``rover-sim export``: run a scenario and write its sensor streams as a KITTI, EuRoC or ROS 2 (MCAP) dataset."""

from __future__ import annotations

import json as jsonlib
from pathlib import Path
from typing import Annotated

import typer

from rover_sim.errors import RoverSimError


def export_cmd(
    scenario: Annotated[str, typer.Argument(help="Scenario name (scenarios/<name>.toml) or path to a TOML file.")],
    format_: Annotated[str, typer.Option("--format", help="kitti | euroc | rosbag2")] = "kitti",
    out: Annotated[Path, typer.Option("--out", help="Output directory (new or empty).")] = Path("runs/export"),
    camera: Annotated[str, typer.Option("--camera", help="navcam | hazcam_front | hazcam_rear")] = "navcam",
    rate_hz: Annotated[
        float | None,
        typer.Option("--rate-hz", help="Render an extra pair at this rate (0 < R <= 8; noise-free, run unchanged)."),
    ] = None,
    at_vo_steps: Annotated[
        bool,
        typer.Option("--at-vo-steps", help="Frames are the pairs the rover takes (default; with VO: the VO pairs)."),
    ] = False,
    seed: Annotated[int | None, typer.Option("--seed", help="Override the scenario seed.")] = None,
    set_: Annotated[
        list[str] | None, typer.Option("--set", help="Override a scenario field: dotted.key=value.")
    ] = None,
    json: Annotated[Path | None, typer.Option("--json", help="Write a summary as JSON to this path.")] = None,
    progress: Annotated[bool, typer.Option("--progress/--no-progress")] = True,
) -> None:
    """Run a scenario (any commands, autonav included) and write a dataset: stereo pairs of --camera, IMU, wheel
    encoders, ground truth (and, in the ROS 2 bag, the onboard estimates). The run's outputs go to OUT/run/."""
    from rover_sim.io.export import check_options, export_scenario

    try:
        check_options(format_, camera, rate_hz, at_vo_steps)
        summary = export_scenario(
            scenario, out, formats=(format_,), camera=camera, rate_hz=rate_hz, seed=seed,
            overrides=list(set_ or []), progress=progress,
        )  # fmt: skip
    except RoverSimError as e:
        typer.secho(f"error: {e}", fg=typer.colors.RED, err=True)
        raise typer.Exit(code=2) from None
    typer.echo(
        f"{summary.format}: {summary.frames} frames of {camera}, {summary.imu_samples} IMU samples over "
        f"{summary.duration_s:.1f} s -> {out}/ (run outputs in {out}/run/)"
    )
    if summary.frames == 0:
        typer.secho(
            f"warning: the rover took no {camera} pairs; use --rate-hz to render frames at a fixed rate",
            fg=typer.colors.YELLOW,
            err=True,
        )
    if json is not None:
        json.parent.mkdir(parents=True, exist_ok=True)
        json.write_text(jsonlib.dumps(summary.to_json(), indent=2))
