"""``rover-sim view --web``: serves on 127.0.0.1 unless told otherwise, leaves no server behind when stopped, and
refuses (one line, exit 2) to start when a port is taken, instead of showing whatever recording that server holds."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rover_sim.cli.status import ExitStatus

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/net/tcp")


@pytest.fixture(scope="module")
def rrd(tmp_path_factory) -> Path:
    import rerun as rr

    path = tmp_path_factory.mktemp("view") / "recording.rrd"
    rec = rr.RecordingStream("rover_sim_view_test")
    rec.save(str(path))
    rec.log("points", rr.Points3D([[0.0, 0.0, 0.0]]))
    rec.flush()
    rec.disconnect()
    return path


def free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def listening() -> dict[int, set[str]]:
    """Port -> the IPv4 addresses listening on it (from /proc/net/tcp: state 0A = LISTEN)."""
    out: dict[int, set[str]] = {}
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        local, state = line.split()[1], line.split()[3]
        if state != "0A":
            continue
        addr_hex, port_hex = local.split(":")
        addr = ".".join(str(int(addr_hex[i : i + 2], 16)) for i in (6, 4, 2, 0))
        out.setdefault(int(port_hex, 16), set()).add(addr)
    return out


def start_view(rrd: Path, *args: str) -> subprocess.Popen:
    env = os.environ | {"PYTHONPATH": str(ROOT)}
    env.pop("DISPLAY", None)
    return subprocess.Popen(
        [sys.executable, "-m", "rover_sim.cli.main", "view", str(rrd), "--web", *args],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # a background job ignores SIGINT
    )


def wait_listening(ports: list[int], proc: subprocess.Popen, timeout_s: float = 60.0) -> dict[int, set[str]]:
    t0 = time.monotonic()
    while not all(p in listening() for p in ports):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout_s, "the viewer did not start listening"
        time.sleep(0.1)
    return listening()


def test_serves_on_localhost_and_sigterm_leaves_no_server(rrd):
    web, grpc = free_ports(2)
    proc = start_view(rrd, "--port", str(web), "--grpc-port", str(grpc))
    try:
        seen = wait_listening([web, grpc], proc)
        assert seen[web] == {"127.0.0.1"} and seen[grpc] == {"127.0.0.1"}, seen  # not 0.0.0.0: not the network
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == ExitStatus.SIGTERM
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=30)
    time.sleep(0.5)
    assert web not in listening() and grpc not in listening()  # the rerun server went with it


def test_a_taken_port_is_refused_in_one_line(rrd):
    web, grpc = free_ports(2)
    with socket.socket() as stale:  # a server still listening there (e.g. an orphaned viewer)
        stale.bind(("127.0.0.1", grpc))
        stale.listen(1)
        proc = start_view(rrd, "--port", str(web), "--grpc-port", str(grpc))
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == ExitStatus.BAD_INPUT, (out, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"error: --grpc-port {grpc}: ") and "in use" in lines[0], err
    assert "serving" not in out and web not in listening()


def test_bind_elsewhere_on_request(rrd):
    web, grpc = free_ports(2)
    proc = start_view(rrd, "--port", str(web), "--grpc-port", str(grpc), "--bind", "0.0.0.0")
    try:
        seen = wait_listening([web, grpc], proc)
        assert seen[web] == {"0.0.0.0"}, seen
        assert "http://127.0.0.1:" in proc.stdout.readline()  # the URL to open on this machine
        proc.send_signal(signal.SIGINT)  # Ctrl-C: the way to stop it, status 0
        assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)  # stops the viewer with it
            proc.wait(timeout=30)
    time.sleep(0.5)
    assert web not in listening()
