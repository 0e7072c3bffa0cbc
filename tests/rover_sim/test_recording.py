"""The rerun recorder: a fake 10-tick traverse through every log method, read back with rerun's own reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from nav.camera import PinholeCamera, StereoRig
from nav.geometry import R_to_quat_wxyz, rpy_to_R, se3
from rover_sim.io.recorder_protocol import NullRecorder, Recorder
from rover_sim.io.recording import RerunRecorder
from rover_sim.io.recording_helpers import terrain_mesh_step
from rover_sim.io.rrd import entity_row_counts
from terrains import Terrain, TerrainRecipe, synthesize

N_TICKS = 10
CAM_TO_ROVER = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # OpenCV camera looking along +x


@pytest.fixture(autouse=True)
def strict_rerun():
    """Rerun only warns on a bad log call by default; make it raise so the tests see it."""
    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(False)


@pytest.fixture(scope="module")
def terrain() -> Terrain:
    return synthesize(TerrainRecipe(size_m=(6, 6), cell_size_m=0.1), seed=0)


def _rig(name: str, mast_tilt_rad: float = 0.0) -> StereoRig:
    R = rpy_to_R(0.0, mast_tilt_rad, 0.0) @ CAM_TO_ROVER
    left = PinholeCamera.from_fov(f"{name}_left", 64, 48, 45.0, se3(R, [0.4, 0.1, 1.0]))
    right = PinholeCamera.from_fov(f"{name}_right", 64, 48, 45.0, se3(R, [0.4, -0.1, 1.0]))
    return StereoRig(left, right)


def _traverse(rec: Recorder, terrain: Terrain, fail_at: int | None = None) -> None:
    """A straight 10-tick drive logged through every method of the Recorder protocol."""
    rec.log_terrain(terrain)
    rec.log_keep_out("wopmay", 1.0, 1.0, 0.5, 0.0)
    rng = np.random.default_rng(0)
    truth = []
    for k in range(N_TICKS):
        if k == fail_at:
            raise RuntimeError("simulated crash mid-traverse")
        t = 0.125 * k
        p = np.array([-2.0 + 0.2 * k, 0.0, float(terrain.height_at(-2.0 + 0.2 * k, 0.0)) + 0.525])
        truth.append(p)
        q = R_to_quat_wxyz(rpy_to_R(0.0, 0.05, 0.01 * k))
        rec.log_rover_pose(t, k, p, q)
        rec.log_camera("navcam", _rig("navcam", mast_tilt_rad=0.3 if k < 5 else 0.5), t_s=t)  # mast moves once
        rec.log_camera("hazcam_front", _rig("hazcam_front", mast_tilt_rad=0.8))
        left = rng.integers(0, 255, (48, 64), dtype=np.uint8)
        disparity = np.full((48, 64), 5.0)
        disparity[0] = np.nan
        rec.log_stereo_images("navcam", t, k, left, np.roll(left, -5, axis=1), disparity)
        rec.log_points("stereo", t, k, p + rng.normal(size=(200, 3)), colors=np.full((200, 3), 200, np.uint8))
        path = np.asarray(truth)
        rec.log_trajectory("truth", t, k, path)
        rec.log_trajectory("dead_reckoning", t, k, path * 1.05)
        rec.log_trajectory("vo", t, k, path + 0.01)
        cx, cy = np.meshgrid(np.arange(-1.0, 1.0, 0.2), np.arange(-1.0, 1.0, 0.2))
        good = rng.random(cx.size)
        good[::7] = np.nan
        rec.log_goodness(t, k, np.column_stack([cx.ravel(), cy.ravel()]), np.zeros(cx.size), good, 0.2)
        arcs = [np.column_stack([np.linspace(0, 1, 5), np.full(5, y), np.zeros(5)]) + p for y in (-0.2, 0.0, 0.2)]
        rec.log_arcs(t, k, arcs, [0.2, 0.9, None], chosen=1 if k % 2 else None)
        uv = rng.uniform(0, 48, (30, 2))
        rec.log_vo_features("navcam", t, k, uv - 1.0, uv, rng.random(30) > 0.2)
        rec.log_scalars(t, k, {"slip": 0.1 * k, "tilt_deg": 3.0, "position_error_m/vo": 0.01 * k, "nan": np.nan})
        if k % 4 == 0:
            rec.log_event(t, k, f"tick {k}", level="WARN" if k else "INFO")


def test_recording_has_every_stream(tmp_path: Path, terrain: Terrain) -> None:
    path = tmp_path / "run.rrd"
    rec = RerunRecorder(path, recording_name="test", jpeg_quality=None)
    try:
        _traverse(rec, terrain)
    finally:
        rec.close()
    rec.close()  # idempotent

    counts = entity_row_counts(path)
    assert counts["/world/rover"] == N_TICKS
    assert counts["/world/terrain"] == 1
    if terrain.rocks:
        assert counts["/world/terrain/rocks"] == 1
    assert counts["/world/rover/visual"] == 1
    assert counts["/world/keep_out/wopmay"] == 1
    # navcam extrinsics: logged twice (the mast moved once), pinholes once; hazcam never moves
    assert counts["/world/rover/navcam/left"] == 1 + 2
    assert counts["/world/rover/navcam/right"] == 1 + 2
    assert counts["/world/rover/hazcam_front/left"] == 1 + 1
    for img in ("left/image", "right/image", "left/depth", "left/features", "left/tracks"):
        assert counts[f"/world/rover/navcam/{img}"] == N_TICKS, img
    assert counts["/world/points/stereo"] == N_TICKS
    for name in ("truth", "dead_reckoning", "vo"):
        assert counts[f"/world/trajectories/{name}/current"] == N_TICKS
        assert counts[f"/world/trajectories/{name}/path/00000"] == N_TICKS - 1  # no strip from a single point
    assert len({p.split("/")[3] for p in counts if p.startswith("/world/trajectories/")}) == 3
    assert counts["/world/goodness"] == N_TICKS
    assert counts["/world/arcs/candidates"] == N_TICKS
    assert counts["/world/arcs/chosen"] == N_TICKS  # strips and clears
    for key in ("slip", "tilt_deg", "position_error_m/vo"):
        assert counts[f"/plots/{key}"] == N_TICKS
    assert "/plots/nan" not in counts
    assert counts["/events"] == 3

    reader = RrdReader(path)
    assert len(reader.recordings()) == 1
    assert len(reader.blueprints()) == 1  # the default layout travels with the file
    assert "world/rover" in reader.store().summary()  # the footer is there: random access works

    by_entity = {c.entity_path: c for c in reader.stream().to_chunks() if c.entity_path == "/world/rover"}
    assert set(by_entity["/world/rover"].timeline_names) >= {"sim_time", "step"}


def test_terrain_and_trajectory_sizes(tmp_path: Path, terrain: Terrain) -> None:
    assert terrain_mesh_step(61, 61) == 1
    assert terrain_mesh_step(2001, 2001) == 7  # 2 * 286^2 < 200k triangles
    path = tmp_path / "blocks.rrd"
    with RerunRecorder(path, segment_points=4, min_spacing_m=0.04) as rec:
        xs = np.linspace(0.0, 1.0, 21)  # 5 cm apart
        track = np.column_stack([xs, np.zeros_like(xs), np.zeros_like(xs)])
        for k in range(1, len(xs) + 1):
            rec.log_trajectory("vo", 0.1 * k, k, track[:k])
        rec.log_trajectory("vo", 3.0, 30, track[:5] + 1.0)  # a rewritten history starts over
    chunks = [c for c in RrdReader(path).stream().to_chunks() if c.entity_path.startswith("/world/trajectories/vo/")]
    blocks = {c.entity_path for c in chunks if "/path/" in c.entity_path}
    assert len(blocks) == 7  # 21 vertices in blocks of 4 sharing their end vertex -> 7 blocks
    lengths = []
    for c in chunks:
        if c.entity_path.endswith("/path/00003"):
            table = c.to_record_batch()
            col = next(n for n in table.schema.names if n.endswith("LineStrips3D:strips"))
            lengths += [len(cell[0]) for cell in table.column(col).to_pylist() if cell]
    assert sorted(lengths) == [2, 3, 4]  # the open block grows, the closed one holds segment_points vertices


def test_recording_survives_an_exception(tmp_path: Path, terrain: Terrain) -> None:
    path = tmp_path / "crash.rrd"
    rec = RerunRecorder(path)
    with pytest.raises(RuntimeError, match="simulated crash"):
        try:
            _traverse(rec, terrain, fail_at=4)
        finally:
            rec.close()
    counts = entity_row_counts(path)
    assert counts["/world/rover"] == 4
    assert counts["/world/rover/navcam/left/image"] == 4
    assert "world/rover" in RrdReader(path).store().summary()
    with pytest.raises(RuntimeError, match="closed"):
        rec.log_rover_pose(1.0, 9, np.zeros(3), np.array([1.0, 0, 0, 0]))


def test_two_recorders_do_not_mix(tmp_path: Path) -> None:
    a, b = RerunRecorder(tmp_path / "a.rrd"), RerunRecorder(tmp_path / "b.rrd")
    a.log_event(0.0, 0, "only in a")
    b.log_rover_pose(0.0, 0, np.zeros(3), np.array([1.0, 0, 0, 0]))
    a.close()
    b.close()
    assert "/events" in entity_row_counts(tmp_path / "a.rrd")
    assert "/events" not in entity_row_counts(tmp_path / "b.rrd")
    assert "/world/rover" not in entity_row_counts(tmp_path / "a.rrd")


def test_bad_arguments_are_refused(tmp_path: Path) -> None:
    with RerunRecorder(tmp_path / "bad.rrd") as rec:
        with pytest.raises(ValueError, match="level"):
            rec.log_event(0.0, 0, "x", level="LOUD")
        with pytest.raises(ValueError, match="log_camera"):
            rec.log_stereo_images(
                "navcam", 0.0, 0, np.zeros((4, 4), np.uint8), np.zeros((4, 4), np.uint8), np.ones((4, 4))
            )
        with pytest.raises(ValueError, match="votes"):
            rec.log_arcs(0.0, 0, [np.zeros((2, 3))], [], None)


def test_null_recorder_accepts_everything(terrain: Terrain) -> None:
    rec = NullRecorder()
    assert isinstance(rec, Recorder)
    _traverse(rec, terrain)
    rec.close()
    assert isinstance(RerunRecorder, type) and issubclass(RerunRecorder, Recorder)


def _high_rate_drive(path: Path, flush_rows: int, n: int) -> None:
    """``n`` ticks of pose, one scalar and a truth track (blocks of 16 vertices), then an event."""
    with RerunRecorder(path, flush_rows=flush_rows, min_spacing_m=0.0, segment_points=16) as rec:
        track = []
        for k in range(n):
            p = np.array([0.05 * k, 0.0, 0.5])
            track.append(p)
            rec.log_rover_pose(0.125 * k, k, p, np.array([1.0, 0.0, 0.0, 0.0]))
            rec.log_scalars(0.125 * k, k, {"tilt_deg": float(k)})
            rec.log_trajectory("truth", 0.125 * k, k, np.asarray(track))
        rec.log_event(0.125 * n, n, "done")


def test_high_rate_streams_are_sent_in_columns(tmp_path: Path) -> None:
    """Poses, scalars and trajectories reach the file in chunks of ``flush_rows`` rows (not a chunk per call, which
    costs ~1.5 kB each), in order, on the simulation timelines only (no wall-clock ``log_time``)."""
    n = 250
    path, unbatched = tmp_path / "batched.rrd", tmp_path / "unbatched.rrd"
    _high_rate_drive(path, 100, n)
    _high_rate_drive(unbatched, 1, n)
    assert entity_row_counts(path) == entity_row_counts(unbatched)  # the same rows, chunked differently
    assert path.stat().st_size < 0.25 * unbatched.stat().st_size
    chunks = list(RrdReader(path).stream().to_chunks())
    pose = [c for c in chunks if c.entity_path == "/world/rover" and not c.is_static]
    assert [c.num_rows for c in pose] == [100, 100, 50]
    xs = []
    for c in pose:
        table = c.to_record_batch()
        col = next(name for name in table.schema.names if name.endswith("Transform3D:translation"))
        xs += [cell[0][0] for cell in table.column(col).to_pylist()]
    np.testing.assert_allclose(xs, 0.05 * np.arange(n), atol=1e-9)
    tilt = [c for c in chunks if c.entity_path == "/plots/tilt_deg"]
    assert sum(c.num_rows for c in tilt) == n and len(tilt) == 3
    assert len([c for c in chunks if c.entity_path == "/world/trajectories/truth/current"]) == 3
    assert len([c for c in chunks if c.entity_path == "/world/trajectories/truth/path/00002"]) == 1  # closed: sent
    for c in chunks:
        assert "log_time" not in c.timeline_names, c.entity_path
        if not c.is_static and c.entity_path != "/__properties":
            assert set(c.timeline_names) == {"sim_time", "step"}, c.entity_path


def test_column_buffer_refuses_mixed_kinds(tmp_path: Path) -> None:
    from rover_sim.io.columns import ColumnBuffer

    rec = rr.RecordingStream("test")
    buf = ColumnBuffer(rec, flush_rows=4)
    buf.add("plots/a", "scalar", 0.0, 0, (1.0,))
    assert buf.pending_rows() == 1
    with pytest.raises(ValueError, match="scalar"):
        buf.add("plots/a", "pose", 0.1, 1, (np.zeros(3), np.array([0, 0, 0, 1.0])))
    with pytest.raises(ValueError, match="kind"):
        buf.add("plots/b", "image", 0.1, 1, (0,))
    with pytest.raises(ValueError, match="flush_rows"):
        ColumnBuffer(rec, flush_rows=0)
