"""The recording's ground in deformable runs (rover_sim/io/rut_log.py): tiles re-logged where ruts change them."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from rover_sim.bench.mobility import slope_terrain, wr_sim
from rover_sim.io.recorder_protocol import NullRecorder
from rover_sim.io.rut_log import RutLog
from rover_sim.sim.drive import Straight, execute


class TileSpy(NullRecorder):
    def __init__(self) -> None:
        self.tiles: list[tuple[str, float, int, np.ndarray]] = []  # key, t_s, mesh_step, world vertices

    def log_ground_tile(self, key, t_s, step, tile, centre_xy_m, mesh_step) -> None:  # noqa: ANN001
        v = np.asarray(tile.to_mesh(step=mesh_step).vertices) + np.array([centre_xy_m[0], centre_xy_m[1], 0.0])
        self.tiles.append((key, t_s, mesh_step, v))


def test_ruts_relog_only_the_tiles_under_the_wheels_throttled():
    sim = wr_sim(slope_terrain("sand", 0.0, 0, size_m=(6.0, 6.0)))
    sim.place(-1.5, 0.0, 0.0)
    rec = TileSpy()
    log = RutLog(sim, rec, tile_m=1.0, every_m=0.5)
    log.log_all(sim.time_s, 0)
    n_tiles = len(rec.tiles)
    assert n_tiles == 36 and all(s == log.coarse_step for _, _, s, _ in rec.tiles)
    rec.tiles.clear()
    paths: list[np.ndarray] = []
    x0 = sim.position_m()[0]

    def tick(s) -> None:  # noqa: ANN001
        log.update(s.time_s, None)
        paths.append(s.wheel_centres_m()[:, :2].copy())

    execute(sim, Straight(1.0), speed_m_s=0.05, on_tick=tick)
    assert sim.position_m()[0] - x0 > 0.8
    log.flush(sim.time_s, None)
    depth = sim.deform.heights_before_m - sim.deform.heights_m()
    assert depth.max() > 2e-3  # the wheels sank
    assert rec.tiles and all(s == 1 for _, _, s, _ in rec.tiles)  # re-logged at full resolution
    # only tiles under the wheel paths (plus the berm / edge cells beside them)
    pts = np.concatenate(paths)
    t = sim.terrain
    j = np.rint((pts[:, 0] + t.half_x_m) / t.cell_size_m).astype(int)
    i = np.rint((pts[:, 1] + t.half_y_m) / t.cell_size_m).astype(int)
    under = {f"t{a}_{b}" for a, b in (log.tile_of_cell(ii, jj) for ii, jj in zip(i, j, strict=True))}
    keys = {k for k, *_ in rec.tiles}
    for key in keys:
        a, b = (int(x) for x in key[1:].split("_"))
        near = any(abs(a - int(u[1:].split("_")[0])) <= 1 and abs(b - int(u[1:].split("_")[1])) <= 1 for u in under)
        assert near, key
    assert len(keys) < n_tiles // 2  # the far ground is not re-logged
    # throttled: ~1 m of travel at one update per 0.5 m (+ the final flush) -> 2-3 rounds, not one per tick
    times = sorted({ts for _, ts, _, _ in rec.tiles})
    assert 2 <= len(times) <= 3 and log.updates == len(times)
    # the last logged mesh of each tile is the deformed heightfield (full resolution: exactly)
    last = {k: v for k, _, _, v in rec.tiles}
    h = sim.deform.heights_m()
    v = np.concatenate(list(last.values()))
    jj = np.rint((v[:, 0] + t.half_x_m) / t.cell_size_m).astype(int)
    ii = np.rint((v[:, 1] + t.half_y_m) / t.cell_size_m).astype(int)
    assert np.allclose(v[:, 0], -t.half_x_m + jj * t.cell_size_m, atol=1e-9)
    assert np.allclose(v[:, 2], h[ii, jj], atol=1e-12)
    assert depth[ii, jj].max() == depth.max()  # and those meshes hold the deepest rut


def test_rigid_run_logs_no_ground_tiles():
    sim = wr_sim(slope_terrain("sand", 0.0, 0, size_m=(6.0, 4.0)), deform=False)
    with pytest.raises(ValueError, match="deformable"):
        RutLog(sim, TileSpy())


class MissionSpy(TileSpy):
    def __init__(self) -> None:
        super().__init__()
        self.terrain_calls: list[bool] = []

    def log_terrain(self, terrain, ground=True) -> None:  # noqa: ANN001
        self.terrain_calls.append(ground)


def _mission_tiles(deformable: bool) -> MissionSpy:
    """purgatory_ripple's first 0.6 m (its pass bounds dropped: they need deformation)."""
    from rover_sim.resources import scenarios_dir
    from rover_sim.runtime.runner import Mission
    from rover_sim.scenario.loading import scenario_from_dict

    data = tomllib.loads((scenarios_dir() / "purgatory_ripple.toml").read_text())
    data["physics"]["deformable"] = deformable
    data.pop("pass")
    rec = MissionSpy()
    mission = Mission(scenario_from_dict(data, overrides=["commands.0.distance_m=0.6"]), recorder=rec)
    try:
        mission.run()
    finally:
        mission.close()
    return rec


def test_mission_logs_ground_tiles_when_deformable_and_the_static_mesh_when_rigid():
    deformable = _mission_tiles(True)
    assert deformable.terrain_calls == [False]  # rocks only: the ground comes as tiles
    keys = [k for k, *_ in deformable.tiles]
    n_tiles = len(set(keys))
    assert n_tiles == 12 * 6  # 1 m tiles of the 12 m x 6 m site, each logged at the start
    relogged = {k for k in keys if keys.count(k) > 1}
    assert 0 < len(relogged) <= n_tiles // 4  # then only where the wheels went
    assert all(k[1] in "23" for k in relogged)  # the rows of tiles around y = 0 (t<row>_<column>)
    rigid = _mission_tiles(False)
    assert rigid.terrain_calls == [True] and rigid.tiles == []
