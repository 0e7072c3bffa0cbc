"""`rover-sim view RUN_DIR [--web]`: open a run's recording in the rerun viewer (web viewer on a headless machine)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Annotated
from urllib.parse import quote

import typer

GRPC_PORT = 9876  # rerun's default gRPC proxy port


def _rerun_binary() -> str:
    beside = Path(sys.executable).with_name("rerun")
    found = str(beside) if beside.is_file() else shutil.which("rerun")
    if not found:
        typer.secho("error: the rerun viewer is not installed: pip install rerun-sdk", fg=typer.colors.RED, err=True)
        raise typer.Exit(code=2)
    return found


def _recording(run: Path) -> Path:
    path = run / "recording.rrd" if run.is_dir() else run
    if not path.is_file() or path.suffix != ".rrd":
        typer.secho(
            f"error: RUN_DIR: {run} holds no recording.rrd (give a run directory or an .rrd file)",
            fg=typer.colors.RED,
            err=True,
        )
        raise typer.Exit(code=2)
    return path


def web_url(web_port: int, grpc_port: int = GRPC_PORT) -> str:
    return f"http://127.0.0.1:{web_port}/?url={quote(f'rerun+http://localhost:{grpc_port}/proxy', safe='')}"


def view_cmd(
    run: Annotated[Path, typer.Argument(help="A run directory (with recording.rrd) or an .rrd file.")],
    web: Annotated[
        bool, typer.Option("--web", help="Serve the web viewer (default when there is no display).")
    ] = False,
    port: Annotated[int, typer.Option("--port", min=1024, max=65535, help="Web viewer HTTP port.")] = 9090,
) -> None:
    """Open a run's recording: the native viewer, or the web viewer on a headless machine (prints its URL)."""
    path = _recording(run)
    headless = not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    cmd = [_rerun_binary(), str(path)]
    if web or headless:
        cmd = [cmd[0], "--serve-web", "--web-viewer-port", str(port), "--port", str(GRPC_PORT), str(path)]
        why = "" if web else " (no display found)"
        typer.echo(f"serving the web viewer{why}: open {web_url(port)} in a browser; Ctrl-C stops it")
    try:
        raise typer.Exit(code=subprocess.call(cmd))
    except KeyboardInterrupt:
        raise typer.Exit(code=0) from None
