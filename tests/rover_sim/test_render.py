"""Offscreen rendering: camera geometry against rendered pixels, depth against ray casts, shadows, segmentation.

All tests share one textured world (``render_world``) and one renderer (``render_renderer``) from conftest.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import MARKER_PIXELS, RAY_GROUPS, ray_to_scene
from scipy import ndimage

import rover_sim  # noqa: F401
from nav.camera import PinholeCamera, transform_points
from rover_sim.errors import RenderingUnavailable
from rover_sim.render.cameras import camera_world_pose
from rover_sim.render.config import ImageNoise, RenderConfig
from rover_sim.render.gl import check_gl
from rover_sim.render.renderer import DN12_MAX, StereoRenderer, bin_average, quantise, terrain_texture
from terrains import TerrainRecipe, rock_albedo, synthesize

pytestmark = pytest.mark.render


def world_T_rover(sim) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = sim.rotation(), sim.position_m()
    return T


def project_world(sim, cam: PinholeCamera, p_world: np.ndarray) -> np.ndarray:
    T_world_cam = world_T_rover(sim) @ cam.T_rover_cam
    return cam.project(transform_points(np.linalg.inv(T_world_cam), p_world[None]))[0]


def bright_blob_centroid(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(u, v) intensity-weighted centroid of the brightest blob inside ``mask`` (no prior on its position)."""
    img = image.astype(float)
    smooth = ndimage.uniform_filter(np.where(mask, img, 0.0), 3)
    v0, u0 = np.unravel_index(np.argmax(np.where(mask, smooth, -1.0)), img.shape)
    win = (slice(max(v0 - 20, 0), v0 + 21), slice(max(u0 - 20, 0), u0 + 21))
    background = float(np.median(img[win][mask[win]]))
    above = (img > 0.5 * (background + img[v0, u0])) & mask
    labels, _ = ndimage.label(above)
    blob = ndimage.binary_dilation(labels == labels[v0, u0], iterations=2) & mask
    w = np.clip(img - background, 0.0, None) * blob
    vv, uu = np.indices(img.shape)
    return np.array([(w * uu).sum() / w.sum(), (w * vv).sum() / w.sum()])


# ------------------------------------------------------------------------------------------- GL availability


def test_render_check_gl_passes_here() -> None:
    check_gl()


def test_render_check_gl_failure_carries_install_hint(monkeypatch) -> None:
    import mujoco

    class NoContext:
        def __init__(self, *args: object) -> None:
            raise RuntimeError("eglInitialize failed")

    monkeypatch.setattr(mujoco, "GLContext", NoContext)
    monkeypatch.setattr(NoContext, "__module__", "mujoco.egl")
    with pytest.raises(RenderingUnavailable, match="apt-get install libegl1 libgl1-mesa-dri"):
        check_gl.__wrapped__()


# ------------------------------------------------------------------------------------------- camera geometry


@pytest.mark.parametrize("pair", ["hazcam_front", "navcam"])
def test_render_marker_appears_where_the_camera_model_projects_it(render_world, render_renderer, pair) -> None:
    """A bright disc painted into the albedo at a known world point lands on its projection (< 1 px), both eyes.

    Checks at once: intrinsics (fovy), extrinsics (incl. the mast and the OpenCV axes), the stereo baseline,
    the world-fixed texture (orientation and scale of the drape) and the image row order.
    """
    sim, renderer = render_world.sim, render_renderer
    renderer.shadows = True
    frame = renderer.render_pair(pair)
    p_world = render_world.markers_xyz[f"{pair}_left"]
    terrain_id = sim.model.geom("terrain").id
    for cam, image in ((frame.rig.left, frame.left), (frame.rig.right, frame.right)):
        expected = project_world(sim, cam, p_world)
        assert np.all((expected > 5) & (expected < 250)), f"marker out of view of {cam.name}: {expected}"
        mask = renderer.render_segmentation(cam.name) == terrain_id
        found = bright_blob_centroid(image, mask)
        assert np.linalg.norm(found - expected) < 1.0, f"{cam.name}: marker at {found}, model says {expected}"
    # the pixel the marker was placed under (conftest) is consistent too
    np.testing.assert_allclose(project_world(sim, frame.rig.left, p_world), MARKER_PIXELS[f"{pair}_left"], atol=1e-3)


def test_render_marker_in_mer_binned_images(render_world) -> None:
    """The MER path (render 1024x1024, average 4x4) keeps the same 256x256 camera model."""
    sim = render_world.sim
    with StereoRenderer(sim, RenderConfig(binning=4)) as renderer:
        frame = renderer.render_pair("navcam")
        mask = renderer.render_segmentation("navcam_left") == sim.model.geom("terrain").id
    expected = project_world(sim, frame.rig.left, render_world.markers_xyz["navcam_left"])
    assert frame.left.shape == (256, 256)
    assert np.linalg.norm(bright_blob_centroid(frame.left, mask) - expected) < 1.0


def test_render_physics_hfield_drape_matches(render_world) -> None:
    """The texture world.py drapes on the physics hfield (what a plain MuJoCo renderer or viewer shows) is
    oriented like the render-only tiles: the navcam marker lands on its projection there too."""
    import mujoco

    sim = render_world.sim
    r = mujoco.Renderer(sim.model, 256, 256)
    try:
        r.update_scene(sim.data, "navcam_left")
        grey = r.render().astype(np.float32) @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
        r.enable_segmentation_rendering()
        seg = r.render()
    finally:
        r.close()
    mask = (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)) & (seg[..., 0] == sim.model.geom("terrain").id)
    cam = stereo_rig_left(sim)
    expected = project_world(sim, cam, render_world.markers_xyz["navcam_left"])
    vv, uu = np.indices(mask.shape)
    near = np.hypot(uu - expected[0], vv - expected[1]) < 40  # the hazcam's marker is in view too (no shadow)
    assert np.linalg.norm(bright_blob_centroid(grey, mask & near) - expected) < 1.0


def stereo_rig_left(sim) -> PinholeCamera:
    from rover_sim.render.cameras import stereo_rig

    return stereo_rig(sim.model, sim.data, "navcam", 256).left


# ------------------------------------------------------------------------------------------- depth


@pytest.mark.parametrize("cam_name", ["hazcam_front_left", "navcam_left", "hazcam_rear_right"])
def test_render_depth_agrees_with_ray_casts(render_world, render_renderer, cam_name) -> None:
    """z-depth of a 16 x 16 pixel grid vs ``mj_ray`` on the physics model (hfield, rocks, rover): within 1 %."""
    sim, renderer = render_world.sim, render_renderer
    depth = renderer.render_depth(cam_name)
    cam = renderer.camera(cam_name)
    T = camera_world_pose(sim.model, sim.data, cam_name)
    grid = np.linspace(4, 251, 16).round().astype(int)
    rel_err, n_sky, n_edge = [], 0, 0
    for v in grid:
        for u in grid:
            ray_cam = cam.ray(np.array([[u, v]], dtype=float))[0]
            rng = ray_to_scene(sim.model, sim.data, T[:3, 3], T[:3, :3] @ ray_cam)
            if not math.isfinite(rng):
                assert np.isinf(depth[v, u]), f"sky at ({u}, {v}) but rendered depth {depth[v, u]}"
                n_sky += 1
                continue
            patch = depth[v - 1 : v + 2, u - 1 : u + 2]
            if not np.all(np.isfinite(patch)) or np.ptp(patch) > 0.05 * patch.min():
                n_edge += 1  # silhouette: the pixel centre may fall either side
                continue
            rel_err.append(abs(depth[v, u] - rng * ray_cam[2]) / (rng * ray_cam[2]))
    assert len(rel_err) > 140 and n_edge < 48  # most of the grid is away from silhouettes and the horizon
    assert max(rel_err) < 0.01, f"worst depth error {max(rel_err):.4f} ({cam_name}, {n_sky} sky pixels)"


# ------------------------------------------------------------------------------------------- shadows


def sun_shadow_grid(sim, renderer, cam_name: str, step: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted shadow on a pixel grid ``step`` apart: a ray from the ground point toward the sun hits something.

    Returns the grid's pixel rows and columns and its state: 0 not terrain, 1 shadowed, 2 sunlit.
    """
    import mujoco

    depth = renderer.render_depth(cam_name)
    seg = renderer.render_segmentation(cam_name)
    cam = renderer.camera(cam_name)
    T = camera_world_pose(sim.model, sim.data, cam_name)
    to_sun = -sim.model.light_dir[sim.model.light("sun").id]
    to_sun = to_sun / np.linalg.norm(to_sun)
    vv, uu = np.mgrid[step // 2 : 256 : step, step // 2 : 256 : step]
    state = np.zeros(vv.shape, dtype=np.int8)
    terrain = (seg[vv, uu] == sim.model.geom("terrain").id) & np.isfinite(depth[vv, uu])
    rays = cam.ray(np.stack([uu[terrain], vv[terrain]], axis=1).astype(float))
    pts = T[:3, 3] + (rays * (depth[vv, uu][terrain] / rays[:, 2])[:, None]) @ T[:3, :3].T
    geomid = np.full(1, -1, dtype=np.int32)
    hit = [mujoco.mj_ray(sim.model, sim.data, p + 0.01 * to_sun, to_sun, RAY_GROUPS, 1, -1, geomid) >= 0 for p in pts]
    state[terrain] = np.where(hit, 1, 2)
    return vv, uu, state


def test_render_rover_shadow_where_geometry_puts_it(render_world, render_renderer) -> None:
    """Sun behind the rover: the navcam sees the rover's shadow exactly where ray casts toward the sun say."""
    sim, renderer = render_world.sim, render_renderer
    vv, uu, state = sun_shadow_grid(sim, renderer, "navcam_left")
    assert 300 < (state == 1).sum() < 0.8 * (state > 0).sum(), "the test scene must show a sizeable rover shadow"
    core_in = ndimage.binary_erosion(state == 1, iterations=2)  # 4 px away from the predicted shadow edge
    core_out = ndimage.binary_erosion(state == 2, iterations=2)
    assert core_in.sum() > 100 and core_out.sum() > 1000
    ratios = {}
    for shadows in (True, False):
        renderer.shadows = shadows
        try:
            img = renderer.render_pair("navcam").left.astype(float)[vv, uu]
        finally:
            renderer.shadows = True
        inside, outside = img[core_in], img[core_out]
        ratios[shadows] = inside.mean() / outside.mean()
        if shadows:
            threshold = 0.5 * (inside.mean() + outside.mean())
            assert (inside < threshold).mean() > 0.97 and (outside > threshold).mean() > 0.97
    # sky / (sky + sun cos i): 0.5 / (0.5 + 1.3 sin 35 deg) = 0.40 on flat ground
    assert ratios[True] < 0.6, ratios
    assert ratios[False] > 0.9, ratios  # control: the dark region is the shadow, not the texture


# ------------------------------------------------------------------------------------------- segmentation, rocks


def test_render_segmentation_names_physics_geoms(render_world, render_renderer) -> None:
    sim, renderer = render_world.sim, render_renderer
    m = sim.model
    haz = renderer.render_segmentation("hazcam_front_left")
    nav = renderer.render_segmentation("navcam_left")
    seen = {m.geom(g).name for g in np.unique(np.r_[haz.ravel(), nav.ravel()]) if g >= 0}
    assert {"terrain", "rock_0000", "wheel_lf_visual", "wheel_rf_visual"} <= seen, seen
    assert (haz[:10] == -1).mean() > 0.9  # sky above the hazcam horizon
    assert all(m.geom_group[m.geom(n).id] != 3 for n in seen)  # collision geoms are never drawn


def test_render_rocks_have_their_own_colour(render_world, render_renderer) -> None:
    rmodel = render_renderer.world.model
    rock = render_world.sim.terrain.rocks[0]
    rgba = rmodel.geom_rgba[rmodel.geom("rock_0000").id]
    level = rock_albedo(rock, render_world.sim.terrain.seed)
    np.testing.assert_allclose(rgba[:3] / rgba[:3].max(), np.array([0.82, 0.70, 0.60]) / 0.82, atol=1e-6)
    assert rgba[0] == pytest.approx(0.82 * level)
    assert rmodel.mat_texid[rmodel.geom_matid[rmodel.geom("rock_0000").id]].max() >= 0  # textured


# ------------------------------------------------------------------------------------------- culling, LOD


def test_render_culling_and_lod_do_not_change_the_picture(render_world, render_renderer) -> None:
    sim = render_world.sim
    render_renderer.shadows = True
    fast = render_renderer.render_pair("navcam")
    assert fast.meta["tiles_drawn"] < len(render_renderer.world.tiles.boxes)
    with StereoRenderer(sim, RenderConfig(cull=False, lod=False, terrain_casts_shadows=True)) as full:
        ref = full.render_pair("navcam")
    diff = np.abs(fast.left.astype(int) - ref.left.astype(int))
    assert diff.mean() < 0.5 and (diff > 8).mean() < 0.002, (diff.mean(), (diff > 8).mean())


def test_render_is_deterministic(render_renderer) -> None:
    a = render_renderer.render_pair("hazcam_rear")
    b = render_renderer.render_pair("hazcam_rear")
    assert np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right)
    assert a.left.dtype == np.uint8 and a.left.shape == (256, 256)


# ------------------------------------------------------------------------------------------- pixel pipeline


def test_render_binning_averages_blocks() -> None:
    img = np.arange(64, dtype=np.float32).reshape(8, 8)
    out = bin_average(img, 4)
    assert out.shape == (2, 2)
    assert out[0, 0] == pytest.approx(img[:4, :4].mean()) and out[1, 1] == pytest.approx(img[4:, 4:].mean())


def test_render_noise_is_seeded_12_bit_read_noise() -> None:
    flat = np.full((256, 256), 100.3, dtype=np.float32)
    assert np.all(quantise(flat, None, None) == 100)
    noise = ImageNoise(read_noise_dn12=32.0, seed=4)
    a = quantise(flat, noise, np.random.default_rng(noise.seed))
    b = quantise(flat, noise, np.random.default_rng(noise.seed))
    assert np.array_equal(a, b) and a.dtype == np.uint8
    expected_std = 32.0 * 255.0 / DN12_MAX  # 2.0 grey levels
    assert a.std() == pytest.approx(expected_std, rel=0.1)
    assert a.mean() == pytest.approx(100.3, abs=0.05)


def test_render_terrain_texture_shape_and_limit() -> None:
    terrain = synthesize(TerrainRecipe(size_m=(4.0, 3.0), cell_size_m=0.1), seed=0)
    rgb = terrain_texture(terrain, 50.0, seed=1)
    assert rgb.shape == (150, 200, 3) and rgb.dtype == np.uint8
    big = synthesize(TerrainRecipe(size_m=(200.0, 200.0), cell_size_m=1.0), seed=0)
    with pytest.raises(ValueError, match="px_per_m"):
        terrain_texture(big, 100.0)
