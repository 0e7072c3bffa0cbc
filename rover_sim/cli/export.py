"""``rover-sim export``: run a scenario and write its sensor streams as a KITTI, EuRoC or ROS 2 (MCAP) dataset.

Exit status as for ``rover-sim run`` (:mod:`rover_sim.cli.status`), except that a failed pass criterion does not fail
an export: 0 the dataset is complete, 2 bad input, 3 the run stopped on an error, 130 Ctrl-C, 143 SIGTERM (the
dataset then holds what was recorded up to the interrupt).
"""

from __future__ import annotations

import json as jsonlib
from pathlib import Path
from typing import Annotated

import typer

from rover_sim.cli.status import RUN_DID_NOT_COMPLETE, ExitStatus, exit_with, fail, guarded, of_reason
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
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Clear a non-empty --out directory first (its contents only).")
    ] = False,
    openvins: Annotated[
        bool,
        typer.Option(
            "--openvins",
            help="euroc: also write OpenVINS's kalibr_imucam_chain.yaml (T_imu_cam) and kalibr_imu_chain.yaml.",
        ),
    ] = False,
) -> None:
    """Run a scenario (any commands, autonav included) and write a dataset: stereo pairs of --camera, IMU, wheel
    encoders, ground truth (and, in the ROS 2 bag, the onboard estimates). The run's outputs go to OUT/run/.
    EuRoC exports carry the Kalibr calibration (camchain-imucam.yaml, imu.yaml) beside mav0/.

    Exit status: 0 written, 2 bad input, 3 the run stopped on an error, 130 Ctrl-C, 143 SIGTERM (what was recorded
    up to the interrupt is kept)."""
    from rover_sim.cli.outdir import check_outputs, prepare_out_dir
    from rover_sim.io.export import check_options, export_scenario
    from rover_sim.scenario.loading import load_scenario

    try:
        check_options(format_, camera, rate_hz, at_vo_steps, openvins)
        check_outputs(("--out", out, "dir"), ("--json", json, "file"))
        sc = load_scenario(scenario, list(set_ or []), seed)  # bad input is reported before --out is touched
        prepare_out_dir(out, overwrite)
    except RoverSimError as e:
        raise fail(e) from None
    with guarded():
        summary = export_scenario(
            sc, out, formats=(format_,), camera=camera, rate_hz=rate_hz, progress=progress, openvins=openvins
        )
    status = of_reason(False, summary.reason) if summary.reason.startswith(RUN_DID_NOT_COMPLETE) else ExitStatus.OK
    what = (
        f"{summary.frames} frames of {camera}, {summary.imu_samples} IMU samples over {summary.duration_s:.1f} s "
        f"-> {out}/ (run outputs in {out}/run/)"
    )
    if status == ExitStatus.OK:
        typer.echo(f"{summary.format}: {what}")
    else:
        why = summary.reason.removeprefix(RUN_DID_NOT_COMPLETE + ": ")
        typer.secho(f"{summary.format}: {why}: the dataset is cut short: {what}", fg=typer.colors.RED, err=True)
    if summary.frames == 0:
        typer.secho(
            f"warning: the rover took no {camera} pairs; use --rate-hz to render frames at a fixed rate",
            fg=typer.colors.YELLOW,
            err=True,
        )
    if json is not None:
        json.parent.mkdir(parents=True, exist_ok=True)
        json.write_text(jsonlib.dumps(summary.to_json(), indent=2))
    exit_with(status)
