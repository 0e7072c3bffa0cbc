"""MER SAD stereo (nav.stereo) on synthetic rectified pairs with known disparity."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nav.camera import PinholeCamera, StereoRig, transform_points
from nav.geometry import se3
from nav.stereo import (
    RowWindow,
    StereoParams,
    bandpass,
    compute_disparity,
    discontinuity_mask,
    disparity_to_xyz_cam,
    edge_mask,
    left_right_mask,
    match_quality_mask,
    quantise,
    range_image,
    row_search_window,
    sad_search,
    speckle_mask,
    stereobm_baseline,
    subpixel_quadratic,
    texture_mask,
    uniqueness_mask,
    xyz_cam_to_rover,
)

SIZE_PX = 256
FOV_DEG = 45.0  # MER navcam
BASELINE_M = 0.20
CAM_HEIGHT_M = 1.5
PITCH_DEG = 35.0


# --------------------------------------------------------------------------------------------------------------
# Synthetic rectified pairs
# --------------------------------------------------------------------------------------------------------------


def rocky_texture(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Band-limited noise like rocky terrain seen at 256^2: fine grain (sigma 1.2 px) over broad shading."""
    fine = cv2.GaussianBlur(rng.standard_normal(shape).astype(np.float32), (0, 0), 1.2)
    broad = cv2.GaussianBlur(rng.standard_normal(shape).astype(np.float32), (0, 0), 8.0)
    return 128.0 + 25.0 * fine / fine.std() + 15.0 * broad / broad.std()


def navcam_rig() -> StereoRig:
    """Navcam-like rectified rig, CAM_HEIGHT_M above a rover frame whose origin is on the ground, pitched down."""
    th = np.radians(PITCH_DEG)
    z_c = np.array([np.cos(th), 0.0, -np.sin(th)])  # optical axis: forward and down
    x_c = np.array([0.0, -1.0, 0.0])  # image right = rover right
    y_c = np.cross(z_c, x_c)
    R = np.stack([x_c, y_c, z_c], axis=1)
    t_left = np.array([0.0, BASELINE_M / 2, CAM_HEIGHT_M])
    left = PinholeCamera.from_fov("navcam_left", SIZE_PX, SIZE_PX, FOV_DEG, se3(R, t_left))
    right = PinholeCamera.from_fov("navcam_right", SIZE_PX, SIZE_PX, FOV_DEG, se3(R, t_left + BASELINE_M * x_c))
    return StereoRig(left, right)


@dataclass(frozen=True)
class SynthPair:
    left: np.ndarray  # uint8
    right: np.ndarray  # uint8
    disparity_px: np.ndarray  # true left-referenced disparity
    occluded: np.ndarray  # left pixels whose scene point the right camera cannot see
    smooth: np.ndarray  # pixels whose window lies on one smooth surface, visible and fully searchable


def ground_disparity_px(rig: StereoRig) -> np.ndarray:
    """Disparity of the flat ground per image row (a plane parallel to the camera x axis: depends on v only)."""
    cam = rig.left
    y = (np.arange(cam.height_px) - cam.cy_px) / cam.fy_px
    th = np.radians(PITCH_DEG)
    return cam.fx_px * rig.baseline_m * (y * np.cos(th) + np.sin(th)) / CAM_HEIGHT_M


def synth_pair(
    seed: int,
    blocks: tuple[tuple[int, int, int, int, float], ...] = ((60, 140, 100, 170, 45.3), (170, 230, 190, 240, 52.6)),
    noise_grey: float = 0.7,
    right_gain: float = 0.9,
    right_offset_grey: float = 8.0,
    params: StereoParams = StereoParams(),
) -> SynthPair:
    """Tilted ground plane seen by `navcam_rig` plus fronto-parallel blocks (rows v0:v1, columns u0:u1, disparity).

    The right image samples each surface's texture at ``u_right + d`` (cubic interpolation, sub-pixel shifts), the
    nearest surface winning; the right camera has a different gain and offset; both get noise and 8-bit rounding.
    """
    rng = np.random.default_rng(seed)
    h_px = w_px = SIZE_PX
    pad = 96
    d_ground = ground_disparity_px(navcam_rig())
    vv, xx = np.mgrid[0:h_px, 0:w_px].astype(np.float32)
    ground = rocky_texture(rng, (h_px, w_px + pad))
    left = ground[:, :w_px].copy()
    right = cv2.remap(ground, xx + d_ground[:, None].astype(np.float32), vv, cv2.INTER_CUBIC)
    truth = np.repeat(d_ground[:, None], w_px, axis=1).astype(np.float32)
    occluded = np.zeros((h_px, w_px), bool)
    for v0, v1, u0, u1, d_block in blocks:
        tex = rocky_texture(rng, (h_px, w_px + pad))
        left[v0:v1, u0:u1] = tex[v0:v1, u0:u1]
        truth[v0:v1, u0:u1] = d_block
        seen = cv2.remap(tex, xx + np.float32(d_block), vv, cv2.INTER_CUBIC)
        rows = slice(v0, v1)
        cover = np.zeros((h_px, w_px), bool)
        cover[rows] = (xx[rows] + d_block >= u0) & (xx[rows] + d_block < u1)
        right[cover] = seen[cover]
        lands = np.zeros((h_px, w_px), bool)  # ground pixels of the left image whose right match is on the block
        lands[rows] = (xx[rows] - d_ground[rows, None] >= u0 - d_block) & (
            xx[rows] - d_ground[rows, None] < u1 - d_block
        )
        lands[v0:v1, u0:u1] = False
        occluded |= lands
    right = right_gain * right + right_offset_grey
    left += rng.normal(0.0, noise_grey, left.shape)
    right += rng.normal(0.0, noise_grey, right.shape)
    hw = params.half_window_px
    gx = cv2.Sobel(truth, cv2.CV_32F, 1, 0)
    gy = cv2.Sobel(truth, cv2.CV_32F, 0, 1)
    near_edge = cv2.dilate((np.abs(gx) + np.abs(gy) > 2.0).astype(np.uint8), np.ones((2 * hw + 3,) * 2, np.uint8))
    smooth = np.zeros((h_px, w_px), bool)
    smooth[hw : h_px - hw, : w_px - hw] = True
    smooth &= np.arange(w_px)[None, :] - hw - 1 >= np.ceil(truth)  # winner and its neighbour searchable
    smooth &= (near_edge == 0) & ~cv2.dilate(occluded.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    u8 = lambda a: np.clip(np.rint(a), 0, 255).astype(np.uint8)  # noqa: E731
    return SynthPair(u8(left), u8(right), truth, occluded, smooth)


def fronto_parallel_pair(seed: int, disparity_px: float, noise_grey: float = 0.7) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    tex = rocky_texture(rng, (SIZE_PX, SIZE_PX + 64))
    vv, xx = np.mgrid[0:SIZE_PX, 0:SIZE_PX].astype(np.float32)
    right = cv2.remap(tex, xx + np.float32(disparity_px), vv, cv2.INTER_CUBIC)
    u8 = lambda a: np.clip(np.rint(a + rng.normal(0, noise_grey, a.shape)), 0, 255).astype(np.uint8)  # noqa: E731
    return u8(tex[:, :SIZE_PX]), u8(right)


@pytest.fixture(scope="module")
def stereo_scene() -> SynthPair:
    return synth_pair(seed=3)


@pytest.fixture(scope="module")
def stereo_scene_disparity(stereo_scene: SynthPair) -> np.ndarray:
    return compute_disparity(stereo_scene.left, stereo_scene.right)


# --------------------------------------------------------------------------------------------------------------
# The SAD engine against a brute-force reference
# --------------------------------------------------------------------------------------------------------------


def brute_force_sad(
    left_q: np.ndarray, right_q: np.ndarray, params: StereoParams, searched: np.ndarray | None = None
) -> np.ndarray:
    """(D, H, W) window SADs, inf where not searched. The window is clipped at the top, bottom and right image
    borders and must lie inside the right image on the left; ``searched`` (D, H) bool limits the disparities of each
    row (default: all)."""
    h_px, w_px = left_q.shape
    hw = params.half_window_px
    L, R = left_q.astype(np.int64), right_q.astype(np.int64)
    vol = np.full((params.num_disparities, h_px, w_px), np.inf)
    for i in range(params.num_disparities):
        s = params.min_disparity + i
        for v in range(h_px):
            if searched is not None and not searched[i, v]:
                continue
            v0, v1 = max(v - hw, 0), min(v + hw + 1, h_px)
            for u in range(s + hw, w_px):
                u1 = min(u + hw + 1, w_px)
                vol[i, v, u] = np.abs(L[v0:v1, u - hw : u1] - R[v0:v1, u - hw - s : u1 - s]).sum()
    return vol


def check_search_against(res, vol: np.ndarray, params: StereoParams) -> None:
    """Winner, its neighbours' scores, the best far score and the right winners of ``res`` agree with ``vol``."""
    n_disp, h_px, w_px = vol.shape
    matched = np.isfinite(vol).any(axis=0)
    idx = np.where(matched, np.argmin(np.where(np.isfinite(vol), vol, 1e9), axis=0), -1)
    np.testing.assert_array_equal(res.index, idx)
    v, u = np.nonzero(matched)
    i = idx[v, u]
    np.testing.assert_array_equal(res.cost[v, u], vol[i, v, u])
    ok = edge_mask(res)[v, u]
    assert ok.sum() > 0.5 * ok.size
    below, above = vol[np.maximum(i - 1, 0), v, u], vol[np.minimum(i + 1, n_disp - 1), v, u]
    np.testing.assert_array_equal(res.cost_minus[v, u][ok], below[ok])
    np.testing.assert_array_equal(res.cost_plus[v, u][ok], above[ok])
    inner = (i > 0) & (i < n_disp - 1) & np.isfinite(below) & np.isfinite(above)  # both neighbours searched
    inner &= (i > res.window.lo[v]) & (i < res.window.hi[v])
    np.testing.assert_array_equal(ok, inner)
    # uniqueness: best score more than 1 px from the winner
    far = np.abs(np.arange(n_disp)[:, None] - i[None, :]) >= 2
    second = np.where(far, vol[:, v, u], np.inf).min(axis=0)
    has_second = np.isfinite(second)
    np.testing.assert_array_equal(res.second_cost[v, u][has_second], second[has_second])
    # right-referenced winner: argmin over the left pixels u_right + s
    for vr in range(h_px):
        for ur in range(w_px):
            scores = [
                vol[k, vr, ur + params.min_disparity + k] if ur + params.min_disparity + k < w_px else np.inf
                for k in range(n_disp)
            ]
            expected = int(np.argmin(scores)) if np.isfinite(scores).any() else -1
            assert res.right_index[vr, ur] == expected


def random_search_pair(seed: int, shape: tuple[int, int] = (14, 40)) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    left_q = rng.integers(0, 63, shape, dtype=np.uint8)
    right_q = np.roll(left_q, -5, axis=1)
    right_q[:, -8:] = rng.integers(0, 63, (shape[0], 8), dtype=np.uint8)
    return left_q, right_q


def test_sad_search_equals_brute_force() -> None:
    params = StereoParams(num_disparities=16, min_disparity=2, window_px=5)
    left_q, right_q = random_search_pair(0)
    check_search_against(sad_search(left_q, right_q, params), brute_force_sad(left_q, right_q, params), params)


def test_sad_search_in_row_windows_equals_brute_force() -> None:
    """Each row searches only its window (monotone windows: each disparity is searched on one band of rows)."""
    params = StereoParams(num_disparities=16, min_disparity=2, window_px=5)
    left_q, right_q = random_search_pair(1)
    lo = np.array([0, 0, 1, 1, 2, 2, 2, 3, 4, 4, 5, 6, 6, 7], np.int32)
    hi = np.array([4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 15, 15], np.int32)
    searched = (np.arange(16)[:, None] >= lo[None, :]) & (np.arange(16)[:, None] <= hi[None, :])
    res = sad_search(left_q, right_q, params, RowWindow(lo, hi))
    check_search_against(res, brute_force_sad(left_q, right_q, params, searched), params)


def test_workspace_reuse_is_stateless(stereo_scene: SynthPair, stereo_scene_disparity: np.ndarray) -> None:
    other = synth_pair(seed=11)
    compute_disparity(other.left, other.right)
    again = compute_disparity(stereo_scene.left, stereo_scene.right)
    np.testing.assert_array_equal(np.isnan(again), np.isnan(stereo_scene_disparity))
    np.testing.assert_array_equal(again[np.isfinite(again)], stereo_scene_disparity[np.isfinite(again)])


@pytest.mark.parametrize("row_window", [True, False])
def test_disparity_does_not_depend_on_prior_buffer_contents(
    stereo_scene: SynthPair, monkeypatch: pytest.MonkeyPatch, row_window: bool
) -> None:
    """The cached pipeline's buffers come from ``np.empty``: whatever the allocator hands back (process history)
    must not reach the result. A fresh pipeline whose uninitialised buffers hold zeros, then random bytes
    (NaNs, infinities, huge values included), gives the same disparity bit for bit."""
    import importlib

    pipeline_mod = importlib.import_module("nav.stereo.pipeline")
    bandpass_mod = importlib.import_module("nav.stereo.bandpass")
    params = StereoParams(row_window=row_window)
    pool = np.random.default_rng(7).integers(0, 256, 2**24, dtype=np.uint8)
    real_empty = np.empty

    def fresh_run(fill: str, offset: int) -> np.ndarray:
        def empty(shape, dtype=float, *args, **kwargs):  # noqa: ANN001, ANN202
            arr = real_empty(shape, dtype, *args, **kwargs)
            raw = arr.reshape(-1).view(np.uint8)
            raw[...] = 0 if fill == "zeros" else pool[offset : offset + raw.size]
            return arr

        monkeypatch.setattr(pipeline_mod._THREAD, "pipelines", {}, raising=False)
        monkeypatch.setattr(bandpass_mod._THREAD, "scratch", {}, raising=False)
        with monkeypatch.context() as m:
            m.setattr(np, "empty", empty)
            return compute_disparity(stereo_scene.left, stereo_scene.right, params)

    ref = fresh_run("zeros", 0)
    assert np.isfinite(ref).mean() > 0.5
    for offset in (0, 1, 4093):
        got = fresh_run("garbage", offset)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
        np.testing.assert_array_equal(got[np.isfinite(got)], ref[np.isfinite(ref)])


# --------------------------------------------------------------------------------------------------------------
# Density and accuracy on a tilted ground plane with blocks
# --------------------------------------------------------------------------------------------------------------


def test_density_and_accuracy_on_textured_scene(stereo_scene: SynthPair, stereo_scene_disparity: np.ndarray) -> None:
    d, s = stereo_scene_disparity, stereo_scene
    valid = np.isfinite(d)
    assert valid[s.smooth].mean() >= 0.90  # density on textured, visible, searchable surfaces
    err = (d - s.disparity_px)[valid]
    assert (np.abs(err) <= 1.0).mean() >= 0.95  # of *all* valid pixels, edges and occlusions included
    smooth_err = (d - s.disparity_px)[valid & s.smooth]
    assert np.sqrt(np.mean(smooth_err**2)) < 0.15  # sub-pixel accuracy on smooth surfaces (quadratic fit)
    assert abs(np.mean(smooth_err)) < 0.03


def test_disparity_follows_the_ground_plane_row_by_row(
    stereo_scene: SynthPair, stereo_scene_disparity: np.ndarray
) -> None:
    """The ground's disparity grows linearly down the image; the per-row median tracks it."""
    d = np.where(stereo_scene.smooth, stereo_scene_disparity, np.nan)
    rows = np.arange(20, 50)  # ground only, above the blocks
    med = np.nanmedian(d[rows], axis=1)
    np.testing.assert_allclose(med, stereo_scene.disparity_px[rows, 200], atol=0.1)


def test_left_right_check_rejects_occluded_pixels(stereo_scene: SynthPair, stereo_scene_disparity: np.ndarray) -> None:
    occluded = stereo_scene.occluded
    assert occluded.sum() > 500
    assert np.isfinite(stereo_scene_disparity[occluded]).mean() < 0.10


def test_left_right_mask_on_a_constructed_case() -> None:
    index = np.full((1, 10), 2, np.int32)
    right_index = np.full((1, 10), 2, np.int32)
    right_index[0, 4] = 5  # right pixel 4 prefers another left pixel: left pixel 6 (= 4 + 2) fails
    index[0, 1] = 3  # u - d < 0: nothing to check against
    ok = left_right_mask(index, right_index, max_diff_px=1)
    assert not ok[0, 6] and not ok[0, 1] and ok[0, 5] and ok[0, 9]
    ok_loose = left_right_mask(index, right_index, max_diff_px=3)
    assert ok_loose[0, 6]


# --------------------------------------------------------------------------------------------------------------
# Sub-pixel interpolation
# --------------------------------------------------------------------------------------------------------------


@settings(max_examples=50, deadline=None)
@given(
    offset=st.floats(-0.5, 0.5),
    curvature=st.floats(0.1, 1e4),
    floor=st.floats(0.0, 1e4),
)
def test_subpixel_quadratic_finds_the_parabola_vertex(offset: float, curvature: float, floor: float) -> None:
    costs = [curvature * (k - offset) ** 2 + floor for k in (-1, 0, 1)]
    got = subpixel_quadratic(*(np.array([c]) for c in costs))
    assert got[0] == pytest.approx(offset, abs=1e-3)


def test_subpixel_quadratic_flat_scores_are_nan() -> None:
    assert np.isnan(subpixel_quadratic(np.array([5.0]), np.array([5.0]), np.array([5.0]))[0])


@pytest.mark.parametrize("fraction", [0.0, 0.25, 0.5, 0.75])
def test_quadratic_subpixel_recovers_a_known_fractional_shift(fraction: float) -> None:
    true_d = 20.0 + fraction
    left, right = fronto_parallel_pair(seed=5, disparity_px=true_d)
    d = compute_disparity(left, right)
    est = d[np.isfinite(d)]
    assert est.size > 0.8 * d.size
    # the parabola on SAD scores pulls slightly towards integers (about 0.07 px at quarter pixels)
    assert np.median(est) == pytest.approx(true_d, abs=0.1)
    if 0 < fraction < 1:
        assert abs(np.median(est) - 20.0) > 0.1 and abs(np.median(est) - 21.0) > 0.1  # not integer-locked


def test_min_disparity_offsets_the_search() -> None:
    left, right = fronto_parallel_pair(seed=6, disparity_px=30.4)
    d = compute_disparity(left, right, StereoParams(min_disparity=16, num_disparities=32))
    assert np.median(d[np.isfinite(d)]) == pytest.approx(30.4, abs=0.1)
    assert np.isfinite(d).mean() > 0.8
    too_far = compute_disparity(left, right, StereoParams(min_disparity=32, num_disparities=16))
    assert np.isfinite(too_far).mean() < 0.02  # the true disparity lies outside the search range


# --------------------------------------------------------------------------------------------------------------
# Texture, uniqueness and blob checks
# --------------------------------------------------------------------------------------------------------------


def test_featureless_image_yields_almost_no_disparity() -> None:
    rng = np.random.default_rng(2)
    flat = np.full((SIZE_PX, SIZE_PX), 140.0)
    left = np.clip(np.rint(flat + rng.normal(0, 0.5, flat.shape)), 0, 255).astype(np.uint8)
    right = np.clip(np.rint(flat + rng.normal(0, 0.5, flat.shape)), 0, 255).astype(np.uint8)
    d = compute_disparity(left, right)
    assert np.isfinite(d).mean() < 0.01


def test_texture_check_is_what_rejects_the_featureless_image() -> None:
    rng = np.random.default_rng(2)
    flat = np.full((64, 96), 140.0) + rng.normal(0, 0.5, (64, 96))
    bp = bandpass(np.clip(np.rint(flat), 0, 255).astype(np.uint8))
    from nav.stereo import texture_mask

    assert texture_mask(bp).mean() < 0.01
    assert texture_mask(bp, StereoParams(texture_threshold=0.0)).mean() == 1.0


def test_uniqueness_rejects_repetitive_texture() -> None:
    """Vertical stripes with an 8 px period match equally well 8 px away: ambiguous, so rejected."""
    rng = np.random.default_rng(4)
    period = np.tile(rng.uniform(60, 200, 8), SIZE_PX // 8 + 8)
    row = cv2.GaussianBlur(period[None, :].astype(np.float32), (0, 0), 0.8)[0]
    tex = np.repeat(row[None, :], SIZE_PX, axis=0)
    u8 = lambda a: np.clip(np.rint(a + rng.normal(0, 0.7, a.shape)), 0, 255).astype(np.uint8)  # noqa: E731
    left, right = u8(tex[:, :SIZE_PX]), u8(tex[:, 20 : 20 + SIZE_PX])  # true disparity 20 (or 12, 28, ...)
    # the full-range search without the other checks that also catch some of these matches
    alone = {"speckle_window_size": 0, "discontinuity_px": 0.0, "row_window": False}
    strict = compute_disparity(left, right, StereoParams(**alone))
    lax = compute_disparity(left, right, StereoParams(uniqueness_ratio=0.0, **alone))
    assert np.isfinite(strict).mean() < 0.05
    assert np.isfinite(lax).mean() > 0.15  # the other checks alone let many of these through
    # with row windows, the half-resolution search applies the test over the whole range first
    assert np.isfinite(compute_disparity(left, right)).mean() < 0.05


def test_speckle_mask_removes_small_islands_only() -> None:
    d = np.full((40, 60), np.nan, np.float32)
    d[5:35, 5:30] = 10.0  # large smooth blob
    d[10:13, 40:43] = 25.0  # 9-pixel island
    d[20, 10] = 14.0  # a single outlier inside the blob
    keep = speckle_mask(d, StereoParams(speckle_window_size=40, speckle_range_px=1.0))
    assert keep[6, 6] and not keep[11, 41] and not keep[20, 10]


def test_discontinuity_mask_drops_both_sides_of_a_depth_edge() -> None:
    v = np.arange(120, dtype=np.float32)[:, None]
    d = np.repeat(10.0 + 0.15 * v, 120, axis=1).astype(np.float32)  # ground: 0.15 px per row, kept
    d[40:80, 40:80] += 4.0  # a rock
    d[5, 5] = np.nan
    keep = discontinuity_mask(d, StereoParams(window_px=9, discontinuity_px=1.5))
    assert keep[10:30].all() and keep[90:110, :30].all() and keep[55:65, 50:70].all()
    assert not keep[55:65, 36:40].any() and not keep[55:65, 40:44].any()  # the ground and the rock at its edge
    assert not keep[36:40, 55:65].any() and not keep[76:80, 55:65].any()
    assert not keep[5, 5] and keep[5, 7]  # NaN stays invalid and does not cut its neighbours
    off = discontinuity_mask(d, StereoParams(discontinuity_px=0.0))
    np.testing.assert_array_equal(off, np.isfinite(d))


def test_match_quality_rejects_a_search_that_misses_the_true_disparity() -> None:
    """A row window that misses the surface still has a best match; the checks must not keep it."""
    left, right = fronto_parallel_pair(seed=5, disparity_px=20.3)
    params = StereoParams()
    bp_l, bp_r = bandpass(left, params), bandpass(right, params)
    q_l, q_r = quantise(bp_l, params), quantise(bp_r, params)
    rows = np.ones(SIZE_PX, np.int32)
    right_window = sad_search(q_l, q_r, params, RowWindow(14 * rows, 26 * rows))
    searched = edge_mask(right_window)
    assert match_quality_mask(right_window, bp_l, params)[searched].mean() > 0.98
    wrong_window = sad_search(q_l, q_r, params, RowWindow(0 * rows, 12 * rows))
    searched = edge_mask(wrong_window)
    good = match_quality_mask(wrong_window, bp_l, params)
    assert good[searched].mean() < 0.4
    # confined to the window, left-right and uniqueness pass most of the wrong matches; all the checks together
    # keep a few per cent
    lr = left_right_mask(wrong_window.index, wrong_window.right_index, params.lr_max_diff_px)
    uq = uniqueness_mask(wrong_window, params)
    assert (lr & uq)[searched].mean() > 0.4
    with np.errstate(invalid="ignore"):
        d = wrong_window.index + subpixel_quadratic(wrong_window.cost_minus, wrong_window.cost, wrong_window.cost_plus)
    d = np.where(searched & good & lr & uq & texture_mask(bp_l, params), d, np.nan).astype(np.float32)
    d[~discontinuity_mask(d, params)] = np.nan
    d[~speckle_mask(d, params)] = np.nan
    assert np.isfinite(d).mean() < 0.05


def test_row_windows_contain_the_surfaces_and_skip_featureless_rows(stereo_scene: SynthPair) -> None:
    params = StereoParams()
    left, right = stereo_scene.left.copy(), stereo_scene.right.copy()
    left[:30], right[:30] = 120, 120  # a featureless band (sky)
    window = row_search_window(bandpass(left, params), bandpass(right, params), params)
    assert (window.hi[:10] < window.lo[:10]).all()  # not searched (the coarse window reaches ~20 px down)
    v, u = np.nonzero(stereo_scene.smooth[40:])
    v += 40
    index = np.rint(stereo_scene.disparity_px[v, u]).astype(int) - params.min_disparity
    inside = (window.lo[v] < index) & (index < window.hi[v])  # the winner and both its neighbours
    assert inside.mean() > 0.99
    width = window.hi - window.lo + 1
    assert (width[np.r_[40:56, 236:256]] <= 10).all()  # ground-only rows: a fraction of the 64 disparities


def test_pipeline_is_the_composition_of_the_steps(stereo_scene: SynthPair, stereo_scene_disparity: np.ndarray) -> None:
    """compute_disparity (buffers, fused OpenCV calls) equals the public step functions applied in order."""
    params = StereoParams()
    bp_l, bp_r = bandpass(stereo_scene.left, params), bandpass(stereo_scene.right, params)
    window = row_search_window(bp_l, bp_r, params)
    search = sad_search(quantise(bp_l, params), quantise(bp_r, params), params, window)
    with np.errstate(invalid="ignore"):
        d = params.min_disparity + search.index + subpixel_quadratic(search.cost_minus, search.cost, search.cost_plus)
    ok = edge_mask(search) & texture_mask(bp_l, params) & match_quality_mask(search, bp_l, params)
    ok &= uniqueness_mask(search, params) & left_right_mask(search.index, search.right_index, params.lr_max_diff_px)
    d = np.where(ok, d, np.nan).astype(np.float32)
    d[~discontinuity_mask(d, params)] = np.nan
    d[~speckle_mask(d, params)] = np.nan
    got = stereo_scene_disparity
    assert (np.isnan(got) != np.isnan(d)).mean() < 1e-4  # a 1/16 px rounding may differ at a threshold
    both = np.isfinite(got) & np.isfinite(d)
    assert both.mean() > 0.75
    np.testing.assert_allclose(got[both], d[both], atol=1e-4)


# --------------------------------------------------------------------------------------------------------------
# XYZ
# --------------------------------------------------------------------------------------------------------------


def test_xyz_round_trip_against_the_rig() -> None:
    rig = navcam_rig()
    rng = np.random.default_rng(7)
    d = rng.uniform(1.0, 60.0, (32, 48)).astype(np.float32)
    d[3, 4] = np.nan
    d[5, 6] = -2.0
    xyz = disparity_to_xyz_cam(d, rig)
    np.testing.assert_allclose(xyz[..., 2], rig.depth_from_disparity(d), rtol=1e-12, equal_nan=True)
    assert np.isnan(xyz[3, 4]).all() and np.isnan(xyz[5, 6]).all()
    ok = np.isfinite(xyz[..., 2])
    uv = rig.left.project(xyz[ok])
    v, u = np.nonzero(ok)
    np.testing.assert_allclose(uv, np.stack([u, v], axis=1), atol=1e-9)
    rover = xyz_cam_to_rover(xyz, rig.left)
    np.testing.assert_allclose(rover[ok], transform_points(rig.left.T_rover_cam, xyz[ok]), atol=1e-12)
    assert np.isnan(rover[3, 4]).all()


def test_range_image_puts_the_ground_at_zero_height(stereo_scene: SynthPair) -> None:
    rig = navcam_rig()
    ground_only = synth_pair(seed=3, blocks=())
    rim = range_image(ground_only.left, ground_only.right, rig)
    assert rim.valid.mean() > 0.7
    z = rim.xyz_rover_m[rim.valid][:, 2]
    assert np.median(np.abs(z)) < 0.01
    assert np.percentile(np.abs(z), 95) < 0.05
    assert rim.points_rover_m().shape == (rim.valid.sum(), 3)
    x = rim.xyz_rover_m[rim.valid][:, 0]
    # ground seen ahead: rays 12.5..57.5 deg below the horizon from 1.5 m reach x = 0.96..6.8 m
    assert 0.9 < x.min() < 1.1 and 6.0 < x.max() < 7.0


# --------------------------------------------------------------------------------------------------------------
# Baseline, parameters, inputs
# --------------------------------------------------------------------------------------------------------------


def test_stereobm_baseline_on_the_scene(stereo_scene: SynthPair) -> None:
    d = stereobm_baseline(stereo_scene.left, stereo_scene.right, 64, 9)
    assert d.dtype == np.float32
    valid = np.isfinite(d)
    assert valid[stereo_scene.smooth].mean() > 0.7  # StereoBM drops the first num_disparities columns
    assert (np.abs(d - stereo_scene.disparity_px)[valid & stereo_scene.smooth] <= 1.0).mean() > 0.95


def test_quantise_cancels_camera_gain() -> None:
    rng = np.random.default_rng(9)
    img = rocky_texture(rng, (64, 64))
    a = quantise(bandpass(np.clip(img, 0, 255).astype(np.uint8)))
    b = quantise(bandpass(np.clip(0.6 * img + 30, 0, 255).astype(np.uint8)))
    assert a.dtype == np.uint8 and a.max() <= 62
    assert np.abs(a.astype(int) - b.astype(int)).mean() < 1.0


@pytest.mark.parametrize(
    "kwargs",
    [
        {"num_disparities": 40},
        {"window_px": 8},
        {"min_disparity": -1},
        {"bandpass_sigma_fine_px": 4.0},
        {"uniqueness_ratio": -0.1},
        {"discontinuity_px": -1.0},
        {"max_sad_ratio": -0.5},
        {"row_window_margin_px": 0},
    ],
)
def test_bad_parameters_raise(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        StereoParams(**kwargs)


def test_bad_images_raise() -> None:
    with pytest.raises(ValueError):
        compute_disparity(np.zeros((8, 8), np.uint8), np.zeros((8, 9), np.uint8))
    with pytest.raises(ValueError):
        compute_disparity(np.zeros((8, 8), np.float32), np.zeros((8, 8), np.float32))
    with pytest.raises(ValueError, match="bin it"):
        compute_disparity(np.zeros((8, 5000), np.uint8), np.zeros((8, 5000), np.uint8))
