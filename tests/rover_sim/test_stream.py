"""Streamed terrain: deterministic tiles, seamless windows, and a drive across a window re-centre
that is indistinguishable from the same drive on a static terrain."""

from __future__ import annotations

import numpy as np
import pytest

import rover_sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from rover_sim.sim.physics import RoverSim
from rover_sim.sim.stream import TerrainStreamer
from terrains import RockSpec, RoughnessSpec, SlopeSpec, TerrainRecipe
from terrains.recipe import StreamSpec
from terrains.stream import StreamedSite, albedo_world

TILE_M = 4.0


def _recipe(cover: float = 0.0) -> TerrainRecipe:
    return TerrainRecipe(
        cell_size_m=0.05,
        slope=SlopeSpec(slope_deg=3.0, azimuth_deg=30.0),
        roughness=RoughnessSpec(rms_m=0.01, correlation_length_m=1.0),
        rocks=RockSpec(cover_fraction=cover, min_height_m=0.05, max_height_m=0.3, exclusion_zones=[]),
        streamed=StreamSpec(
            tile_m=TILE_M, window_tiles=3, rock_slots=16, hill_amplitude_m=0.5, crater_density_per_km2=30.0
        ),  # fmt: skip
    )


def test_tile_rebuilt_after_eviction_is_byte_identical() -> None:
    site = StreamedSite(_recipe(cover=0.1), seed=11, cache_tiles=2)
    first = site.tile(2, -1)
    assert first.rocks, "the recipe should put rocks on a 4 m tile at 10 % cover"
    for k in range(4):  # evict it
        site.tile(10 + k, 10)
    assert (2, -1) not in site._cache  # noqa: SLF001 - checking the eviction happened
    again = site.tile(2, -1)
    assert again is not first and again.digest() == first.digest()
    assert StreamedSite(_recipe(cover=0.1), seed=12).tile(2, -1).digest() != first.digest()


def test_windows_agree_on_shared_ground_and_albedo() -> None:
    site = StreamedSite(_recipe(), seed=3)
    a, b = site.window((0, 0)), site.window((1, 1))
    x, y = np.meshgrid(np.linspace(0.0, 5.0, 23), np.linspace(0.0, 5.0, 19))  # inside both windows
    np.testing.assert_allclose(a.height_at(x, y), b.height_at(x, y), rtol=0, atol=1e-12)
    gx, gy = np.meshgrid(a.xs_m[::7], a.ys_m[::5])  # at grid nodes the window holds the exact relief
    np.testing.assert_allclose(a.height_at(gx, gy), site.relief_m(gx, gy), rtol=0, atol=1e-9)
    # no seam between tiles: steps across a tile edge are like steps inside a tile
    steps = np.abs(np.diff(a.heights_m, axis=1))
    edge = site.tile_cells - 1
    assert steps[:, edge].max() < 3.0 * steps[:, : edge - 1].max()
    np.testing.assert_array_equal(albedo_world(x, y, 3), albedo_world(x.copy(), y.copy(), 3))


def _drive(streamed: bool, seconds: float = 95.0, soil_model: str = "bekker") -> tuple[np.ndarray, np.ndarray, int]:
    """Drive +x from x = 0.5 m over 2 m tiles (a 6 m window): the rover leaves the window the model was compiled
    with, so contacts must follow the moved heightfield. The reference drives the same ground as one static 10 m
    window. Returns (positions, wheel loads, re-centres). With ``soil_model="wong_reece"`` the wheels stand on
    ground plates placed from the heightfield (sim/ground_plates.py), which must follow the moved window too."""
    recipe = _recipe()
    recipe = recipe.model_copy(update={"streamed": recipe.streamed.model_copy(update={"tile_m": 2.0})})
    st = TerrainStreamer(recipe, seed=5)
    window = st.initial_window(0.5, 0.0)
    if not streamed:
        wide = recipe.model_copy(update={"streamed": recipe.streamed.model_copy(update={"window_tiles": 5})})
        window = StreamedSite(wide, seed=5).window((1, 0))
    sim = RoverSim(window, streamer=st if streamed else None, soil_model=soil_model)
    sim.place(0.5, 0.0, 0.0, settle_s=1.0)
    rate = np.full(6, 0.04 / 0.125)
    pos, loads = [], []
    for _ in range(int(seconds * 8)):
        sim.step(rate, 25)
        pos.append(sim.position_m())
        loads.append(sim.ground_truth().wheel_load_n)
    return np.array(pos), np.array(loads), st.recentres


@pytest.mark.parametrize("soil_model", ["bekker", "wong_reece"])
def test_drive_across_window_recentres_is_seamless(soil_model: str) -> None:
    pos_s, load_s, recentres = _drive(streamed=True, soil_model=soil_model)
    pos_r, load_r, _ = _drive(streamed=False, soil_model=soil_model)  # the same ground, never re-centred
    assert recentres >= 2 and pos_s[-1, 0] > 3.5  # beyond the window the model was compiled with
    assert np.abs(pos_s - pos_r).max() < 1e-3  # no jump in pose
    assert np.abs(load_s - load_r).max() < 0.02 * load_r.mean()  # no spike in wheel load
    assert np.abs(np.diff(pos_s[:, 2])).max() < 1e-3


def test_streamed_deformation_is_refused() -> None:
    st = TerrainStreamer(_recipe(), seed=5)
    sim = RoverSim(st.initial_window(0.0, 0.0), streamer=st, soil_model="wong_reece")
    with pytest.raises(ValueError, match="streamed"):
        sim.enable_deformation()


SUN = np.array([0.4, -0.3, -0.87])  # the way sunlight travels (site frame)


@pytest.mark.parametrize("multiscale", [False, True], ids=["classic", "multiscale"])
def test_window_textures_agree_texel_for_texel(multiscale: bool) -> None:
    site = StreamedSite(_recipe(), seed=3)
    a, b = site.window((0, 0)), site.window((1, 0))
    kw = {"multiscale": multiscale, "sun_direction": SUN}
    ta, tb = site.window_albedo(a, 40.0, **kw), site.window_albedo(b, 40.0, **kw)
    assert ta.shape == (round(2 * a.half_y_m * 40), round(2 * a.half_x_m * 40))
    shift = site.tile_cells * 2  # one tile of texels at 2 texels per 5 cm cell
    np.testing.assert_array_equal(ta[:, shift:], tb[:, : ta.shape[1] - shift])


def test_multiscale_tiles_are_the_site_regolith_and_come_back_identical() -> None:
    """The streamed regolith is ``terrains.albedo_tile`` on the tiles' texel lattice: two tiles side by side equal
    one regolith tile spanning both (no seam, up to float rounding), and a tile evicted and rebuilt is
    byte-identical; a moved sun re-shades it."""
    from terrains import albedo_tile

    site = StreamedSite(_recipe(), seed=3, cache_tiles=1)
    first = site.albedo_tile(1, -2, 2, multiscale=True, sun_direction=SUN).copy()
    east = site.albedo_tile(2, -2, 2, multiscale=True, sun_direction=SUN)  # evicts the first (cache of 1)
    m = site.tile_cells * 2
    both = albedo_tile(TILE_M, -2 * TILE_M, 2 * m, m, 40.0, 3, sun_direction=SUN)
    np.testing.assert_allclose(np.hstack([first, east]), both, rtol=0, atol=1e-5)
    again = site.albedo_tile(1, -2, 2, multiscale=True, sun_direction=SUN)
    assert again.tobytes() == first.tobytes()
    lower_sun = site.albedo_tile(1, -2, 2, multiscale=True, sun_direction=np.array([0.9, 0.0, -0.44]))
    assert not np.allclose(lower_sun, first, atol=1e-3)
    assert not np.allclose(site.albedo_tile(1, -2, 2), first, atol=1e-2)  # the classic albedo differs


def test_tiles_are_logged_once_and_compactly(tmp_path) -> None:
    from rover_sim.io.recording import RerunRecorder
    from rover_sim.io.rrd import entity_row_counts

    st = TerrainStreamer(_recipe(cover=0.1), seed=5)
    w0 = st.initial_window(0.0, 0.0)
    first = st.new_tiles(w0)
    assert len(first) == 9 and st.new_tiles(w0) == []  # each tile handed out once
    again = st.new_tiles(st.site.window((1, 0)))
    assert sorted(k for k, _ in again) == ["t2_-1", "t2_0", "t2_1"]
    path = tmp_path / "tiles.rrd"
    with RerunRecorder(path) as rec:
        for key, tile in first + again:
            rec.log_terrain_tile(key, tile)
    rows = entity_row_counts(path)
    assert rows["/world/terrain/tiles/t0_0"] == 1 and "/world/terrain/tiles/t2_1" in rows
    assert path.stat().st_size < 12 * 60_000  # about 60 kB a 4 m tile with its rocks, at most


def _rock_drive(midphase: bool, seconds: float = 30.0) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Drive +x through a dense rock field over 2 m tiles (re-centres move the hfield and the rock pool)."""
    import mujoco

    recipe = _recipe(cover=0.25)
    recipe = recipe.model_copy(
        update={"streamed": recipe.streamed.model_copy(update={"tile_m": 2.0, "rock_slots": 64})}
    )
    st = TerrainStreamer(recipe, seed=5)
    sim = RoverSim(st.initial_window(0.5, 0.0), streamer=st)
    if not midphase:
        sim.model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_MIDPHASE)
    sim.place(0.5, 0.0, 0.0, settle_s=1.0)
    rate = np.full(6, 0.04 / 0.125)
    qpos, ncon, rock_ticks = [], [], 0
    for _ in range(int(seconds * 8)):
        sim.step(rate, 25)
        qpos.append(sim.data.qpos.copy())
        ncon.append(sim.data.ncon)
        rock_ticks += bool(sim.rock_contacts())
    return np.array(qpos), np.array(ncon), rock_ticks, st.recentres


def test_midphase_with_rebuilt_tree_matches_the_all_pairs_test() -> None:
    """The world body's bounding-volume tree is rebuilt after each window move (sim/bvh.py), so MuJoCo's midphase
    can stay on: the same drive with the midphase switched off (every geom pair tested) is bit-identical."""
    q_on, n_on, rocks_on, recentres = _rock_drive(midphase=True)
    q_off, n_off, rocks_off, _ = _rock_drive(midphase=False)
    assert recentres >= 1 and rocks_on > 0  # the drive moved the window and touched rocks
    np.testing.assert_array_equal(q_on, q_off)
    np.testing.assert_array_equal(n_on, n_off)
    assert rocks_on == rocks_off


def test_rebuilt_tree_bounds_every_moved_geom() -> None:
    from rover_sim.sim.bvh import world_boxes

    st = TerrainStreamer(_recipe(cover=0.1), seed=5)
    sim = RoverSim(st.initial_window(0.0, 0.0), streamer=st)
    st.apply(sim.model, st.site.window((3, -2)))  # far from where the model was compiled
    m = sim.model
    adr, num = int(m.body_bvhadr[0]), int(m.body_bvhnum[0])
    leaves = m.bvh_nodeid[adr : adr + num]
    geoms = leaves[leaves >= 0]
    centres, halves = world_boxes(m, geoms)
    root = m.bvh_aabb[adr]
    assert (np.abs(centres - root[:3]) + halves <= root[3:] + 1e-9).all()  # the root holds every leaf box
    for node in range(num):  # every inner box holds its children's boxes
        for ch in m.bvh_child[adr + node]:
            if ch >= 0:
                p, c = m.bvh_aabb[adr + node], m.bvh_aabb[adr + ch]
                assert (np.abs(c[:3] - p[:3]) + c[3:] <= p[3:] + 1e-9).all()
