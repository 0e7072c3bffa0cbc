"""A streamed window's render model is moved in place (rover_sim/render/window.py), not rebuilt, and draws what a
freshly built render model of the new window draws, up to float32 vertex rounding."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from rover_sim.render.renderer import StereoRenderer
from rover_sim.render.tiles import tile_meshes, write_tile_meshes
from rover_sim.runtime.runner import Mission
from rover_sim.scenario.loading import scenario_from_dict

pytestmark = pytest.mark.render

ROCKY_STREAMED = {
    "name": "rocky_streamed",
    "seed": 5,
    "terrain": {
        "cell_size_m": 0.05,
        "roughness": {"rms_m": 0.01, "correlation_length_m": 1.0},
        "rocks": {"cover_fraction": 0.06, "min_height_m": 0.08, "max_height_m": 0.3},
        "material": {"kind": "sand"},
        "streamed": {"tile_m": 2.0, "window_tiles": 3, "rock_slots": 64},
    },
    "appearance": {"texture_px_per_m": 20},
    "start": {"x_m": 0.5},
    "nav": {"vo": False, "image_noise": False},
    "commands": [{"type": "drive", "distance_m": 1.0}],
}


def _diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(a.astype(int) - b.astype(int)).max(axis=2)


def test_a_moved_window_draws_what_a_fresh_render_model_draws() -> None:
    mission = Mission(scenario_from_dict(ROCKY_STREAMED))
    try:
        sim, r = mission.world.sim, mission.renderer
        r.render_rgb("navcam_left")
        model, version = r.world.model, sim.terrain_version
        while sim.terrain_version == version:
            sim.step(np.full(6, 0.4), 50)
        moved = r.render_rgb("navcam_left")
        assert r.world.model is model and r.world.terrain_version == sim.terrain_version  # in place, no rebuild
        fresh = StereoRenderer(sim, r.config, lens=r.lens)
        try:
            want = fresh.render_rgb("navcam_left")
            d = _diff(moved, want)
            print(f"moved vs fresh: {(d > 2).mean():.4f} of pixels > 2 levels, mean {d.mean():.3f}")
            assert (d > 2).mean() < 0.005 and d.mean() < 0.3, (float((d > 2).mean()), float(d.mean()))
            assert len(r.world.rock_ids) == len(fresh.world.rock_ids) > 0
            np.testing.assert_allclose(r.world.rock_boxes, fresh.world.rock_boxes)
            np.testing.assert_allclose(r.world.tiles.boxes, fresh.world.tiles.boxes, atol=1e-6)
            # the comparison sees stale ground: the previous window's meshes written back differ a lot
            tx, ty = sim.terrain.window_index
            previous = sim.streamer.site.window((tx - 1, ty))  # the rover drove east into this window
            _, old = tile_meshes(previous, r.config.terrain_tile_m, r.config.max_terrain_tiles)
            assert write_tile_meshes(model, old)
            for ctx in r.contexts:
                with ctx._gl_context.as_current():
                    for tm in old:
                        mujoco.mjr_uploadMesh(model, ctx._mjr_context, model.mesh(tm.name).id)
            stale = r.render_rgb("navcam_left")
            print(f"stale vs fresh: {(_diff(stale, want) > 2).mean():.4f} of pixels > 2 levels")
            assert (_diff(stale, want) > 2).mean() > 0.05
        finally:
            fresh.close()
    finally:
        mission.close()
