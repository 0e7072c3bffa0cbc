"""`rover-sim view RUN_DIR [--web]`: open a run's recording in the rerun viewer (web viewer on a headless machine).

The web viewer is a ``rerun --serve-web`` child process: an HTTP server for the viewer (``--port``, default 9090)
and a gRPC proxy holding the recording (``--grpc-port``, default 9876), both bound to ``--bind`` (default 127.0.0.1:
only this machine can connect; reach it from elsewhere through an SSH tunnel, or bind another address on purpose).
Before starting, both ports are checked: a port already taken (typically a server left over from an earlier
``view`` that was killed) would make the browser show *that* server's recording, so it is refused in one line.
Ctrl-C or SIGTERM stops the child too, and the child is asked to stop if this process dies first (Linux).
"""

from __future__ import annotations

import ctypes
import errno
import os
import shutil
import signal
import socket
import subprocess
import sys
from pathlib import Path
from typing import Annotated
from urllib.parse import quote

import typer

from rover_sim import interrupts
from rover_sim.cli.status import ExitStatus, fail, of_interrupt

GRPC_PORT = 9876  # rerun's default gRPC proxy port
WEB_PORT = 9090  # rerun's default web viewer port
DEFAULT_BIND = "127.0.0.1"
STOP_TIMEOUT_S = 5.0  # after SIGTERM, the viewer is killed if it has not exited within this time
PR_SET_PDEATHSIG = 1  # prctl(2): the signal the child receives when its parent dies


def _rerun_binary() -> str:
    """The rerun executable: the binary inside the ``rerun_cli`` package when there is one (the ``rerun`` script
    beside Python is a wrapper that runs it as a child of its own), else the ``rerun`` found beside Python or on
    PATH."""
    try:
        import rerun_cli

        binary = Path(rerun_cli.__file__).with_name("rerun.exe" if os.name == "nt" else "rerun")
        if binary.is_file() and os.access(binary, os.X_OK):
            return str(binary)
    except ImportError:
        pass
    beside = Path(sys.executable).with_name("rerun")
    found = str(beside) if beside.is_file() else shutil.which("rerun")
    if not found:
        raise fail("the rerun viewer is not installed: pip install rerun-sdk")
    return found


def _recording(run: Path) -> Path:
    path = run / "recording.rrd" if run.is_dir() else run
    if not path.is_file() or path.suffix != ".rrd":
        raise fail(f"RUN_DIR: {run} holds no recording.rrd (give a run directory or an .rrd file)")
    return path


def web_url(web_port: int, grpc_port: int = GRPC_PORT, host: str = DEFAULT_BIND) -> str:
    """The address to open: the web viewer, told where the gRPC proxy with the recording is."""
    if host in ("0.0.0.0", "::", ""):
        host = "127.0.0.1"
    elif ":" in host:
        host = f"[{host}]"  # an IPv6 address in a URL
    proxy = quote(f"rerun+http://{host}:{grpc_port}/proxy", safe="")
    return f"http://{host}:{web_port}/?url={proxy}"


def port_problem(bind: str, port: int) -> str | None:
    """Why ``bind:port`` cannot be listened on (in use, or not an address of this machine), or None if it can."""
    family = socket.AF_INET6 if ":" in bind else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as servers do: a closed server's TIME_WAIT is fine
        try:
            s.bind((bind, port))
            s.listen(1)
        except OSError as e:
            if e.errno == errno.EADDRINUSE:
                return "already in use"
            return e.strerror or str(e)
    return None


def check_ports(bind: str, ports: dict[str, int]) -> None:
    """Refuse (one line, exit 2) if any of ``ports`` (option -> port) cannot be listened on at ``bind``."""
    for option, port in ports.items():
        problem = port_problem(bind, port)
        if problem == "already in use":
            raise fail(
                f"{option} {port}: {bind}:{port} is already in use (a rerun viewer left running by an earlier "
                f"`rover-sim view`? stop it, or choose other ports with --port/--grpc-port); it would show that "
                "server's recording, not this one"
            )
        if problem:
            raise fail(f"--bind {bind}: cannot listen on {bind}:{port} ({problem})")


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """The viewer gets SIGTERM when this process dies, however it dies (Linux; elsewhere a no-op)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
        except (OSError, AttributeError):
            pass


def _signal_group(child: subprocess.Popen, sig: int) -> None:
    """``sig`` to the child's process group (the viewer and anything it started), or to the child alone."""
    try:
        if os.name == "posix":
            os.killpg(child.pid, sig)
        else:  # pragma: no cover
            child.send_signal(sig)
    except ProcessLookupError:
        pass


def stop(child: subprocess.Popen) -> None:
    """Terminate the viewer's process group and wait for the viewer (killed after ``STOP_TIMEOUT_S``)."""
    if child.poll() is None:
        _signal_group(child, signal.SIGTERM)
        try:
            child.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            _signal_group(child, signal.SIGKILL)
            child.wait()
    _signal_group(child, signal.SIGKILL)  # whatever of the group outlived the viewer itself


def run_viewer(cmd: list[str]) -> int:
    """Run the viewer until it exits; Ctrl-C (status 0: the way to stop it) or SIGTERM (143) stop it first."""
    with interrupts.sigterm_raises():
        posix = os.name == "posix"  # its own process group, so that stop() reaches everything it runs
        child = subprocess.Popen(cmd, start_new_session=posix, preexec_fn=_die_with_parent if posix else None)
        try:
            return child.wait()
        except KeyboardInterrupt as e:
            stop(child)
            return int(ExitStatus.OK) if of_interrupt(e) == ExitStatus.SIGINT else int(ExitStatus.SIGTERM)
        finally:
            stop(child)


def view_cmd(
    run: Annotated[Path, typer.Argument(help="A run directory (with recording.rrd) or an .rrd file.")],
    web: Annotated[
        bool, typer.Option("--web", help="Serve the web viewer (default when there is no display).")
    ] = False,
    port: Annotated[int, typer.Option("--port", min=1024, max=65535, help="Web viewer HTTP port.")] = WEB_PORT,
    grpc_port: Annotated[
        int, typer.Option("--grpc-port", min=1024, max=65535, help="Web viewer: gRPC port serving the recording.")
    ] = GRPC_PORT,
    bind: Annotated[
        str,
        typer.Option(
            "--bind",
            help="Web viewer: address to listen on (0.0.0.0: every interface, reachable by anyone "
            "who can reach this machine).",
        ),
    ] = DEFAULT_BIND,  # fmt: skip
) -> None:
    """Open a run's recording: the native viewer, or the web viewer on a headless machine (prints its URL)."""
    path = _recording(run)
    headless = not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    cmd = [_rerun_binary(), str(path)]
    if web or headless:
        if port == grpc_port:
            raise fail(f"--port {port} and --grpc-port {grpc_port}: the two servers need different ports")
        check_ports(bind, {"--port": port, "--grpc-port": grpc_port})
        cmd = [cmd[0], "--serve-web", "--bind", bind, "--web-viewer-port", str(port), "--port", str(grpc_port),
               str(path)]  # fmt: skip
        why = "" if web else " (no display found)"
        typer.echo(f"serving the web viewer{why} on {bind}: open {web_url(port, grpc_port, bind)} in a browser; "
                   "Ctrl-C stops it")  # fmt: skip
    raise typer.Exit(code=run_viewer(cmd))
