"""Stereo at any size: the SAD engines are exact for large and non-square pairs (the compiled
engine; the OpenCV engine with or without the SAD volume), and full-resolution pairs run end to end (library and
``rover-sim stereo``)."""

from __future__ import annotations

import importlib

import cv2
import numpy as np
import pytest
from test_stereo import brute_force_sad, check_search_against, random_search_pair, synth_pair
from typer.testing import CliRunner

from nav.stereo import RowWindow, StereoParams, compute_disparity, sad_search
from nav.stereo.params import NO_MATCH

sad_mod = importlib.import_module("nav.stereo.sad")
pipeline_mod = importlib.import_module("nav.stereo.pipeline")


ENGINE_MODES = ["fused", "volume", "rolling"]


def use_engine(monkeypatch: pytest.MonkeyPatch, mode: str) -> None:
    """The compiled engine ("fused"), or the OpenCV engine with the SAD volume kept ("volume", small searches) or
    with the rolling neighbours ("rolling", large searches); the cached pipelines are dropped."""
    monkeypatch.setattr(pipeline_mod, "SAD_ENGINE", "fused" if mode == "fused" else "opencv")
    if mode == "rolling":
        monkeypatch.setattr(sad_mod, "VOLUME_BUDGET_BYTES", 0)
    monkeypatch.setattr(pipeline_mod._THREAD, "pipelines", {}, raising=False)


@pytest.fixture(params=ENGINE_MODES)
def engine_mode(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Run the test with each engine (see :func:`use_engine`)."""
    use_engine(monkeypatch, request.param)
    return request.param


def _engine(shape: tuple[int, int], params: StereoParams):  # noqa: ANN202
    return pipeline_mod._pipeline(shape, params).engine


@pytest.mark.parametrize("shape", [(14, 40), (23, 17)])
def test_sad_search_equals_brute_force_in_every_engine(engine_mode: str, shape: tuple[int, int]) -> None:
    params = StereoParams(num_disparities=16, min_disparity=2, window_px=5)
    left_q, right_q = random_search_pair(3, shape)
    res = sad_search(left_q, right_q, params)
    assert _engine(shape, params).rolling == (engine_mode == "rolling")
    check_search_against(res, brute_force_sad(left_q, right_q, params), params)


def test_row_windows_equal_brute_force_in_every_engine(engine_mode: str) -> None:
    """Non-monotone windows (a disparity searched on several bands of rows, merged or not)."""
    params = StereoParams(num_disparities=16, min_disparity=0, window_px=3)
    left_q, right_q = random_search_pair(4, (60, 45))
    rng = np.random.default_rng(5)
    lo = rng.integers(0, 9, 60).astype(np.int32)
    hi = (lo + rng.integers(2, 8, 60)).astype(np.int32)
    hi[10:12] = -1  # rows not searched
    searched = (np.arange(16)[:, None] >= lo[None, :]) & (np.arange(16)[:, None] <= hi[None, :])
    res = sad_search(left_q, right_q, params, RowWindow(lo, hi))
    vol = brute_force_sad(left_q, right_q, params, searched)
    # rows in merged bands may be searched at a few more disparities: compare only the winners inside the window
    idx = np.argmin(np.where(np.isfinite(vol), vol, 1e9), axis=0)
    inside = searched.any(axis=0)[:, None] & (res.index > lo[:, None]) & (res.index < hi[:, None])
    assert inside.mean() > 0.3
    np.testing.assert_array_equal(res.index[inside], idx[inside])
    v, u = np.nonzero(inside)
    i = idx[v, u]
    np.testing.assert_array_equal(res.cost[v, u], vol[i, v, u])
    for got, expected in ((res.cost_minus, vol[i - 1, v, u]), (res.cost_plus, vol[i + 1, v, u])):
        np.testing.assert_array_equal(np.where(got[v, u] >= NO_MATCH, np.inf, got[v, u]), expected)


def test_every_engine_gives_the_same_disparity(monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled engine and the OpenCV engine's rolling neighbours reproduce the OpenCV volume's result bit for
    bit through the whole pipeline (row windows)."""
    scene = synth_pair(seed=3)
    use_engine(monkeypatch, "volume")
    ref = compute_disparity(scene.left, scene.right)
    assert np.isfinite(ref).mean() > 0.5
    for mode in ("fused", "rolling"):
        use_engine(monkeypatch, mode)
        np.testing.assert_array_equal(compute_disparity(scene.left, scene.right), ref)


def _exact_window_sums(diff: np.ndarray, hw: int) -> np.ndarray:
    """Window sums of a zero-padded (top, bottom, right) |L - R| image, int64, clipped like the engine."""
    h_px, w_px = diff.shape
    pad = np.zeros((h_px + 2 * hw, w_px + 2 * hw), np.int64)
    pad[hw : hw + h_px, hw : hw + w_px] = diff
    c = np.zeros((pad.shape[0] + 1, pad.shape[1] + 1), np.int64)
    c[1:, 1:] = pad.cumsum(0).cumsum(1)
    win = 2 * hw + 1
    return c[win:, win:] - c[:-win, win:] - c[win:, :-win] + c[:-win, :-win]


@pytest.mark.parametrize("mode", ["fused", "rolling"])
def test_2048_pair_is_exact_where_float32_sums_are_not(monkeypatch: pytest.MonkeyPatch, mode: str) -> None:
    """A 2048x2048 pair of maximal quantised values (0..62), 21 px window: float32 integral images round (their
    sums pass 2^24), yet every winner and its neighbours' scores equal the exact integer reference (the compiled
    engine; the OpenCV engine's rolling path, as at 4096 px)."""
    use_engine(monkeypatch, mode)
    monkeypatch.setattr(sad_mod, "VOLUME_BUDGET_BYTES", 64 * 2**20)
    n, hw, n_disp = 2048, 10, 16  # the volume would be 256 MB: over the patched budget, rolling neighbours
    params = StereoParams(num_disparities=n_disp, window_px=2 * hw + 1)
    rng = np.random.default_rng(11)
    left_q = rng.integers(0, 63, (n, n), dtype=np.uint8)
    right_q = np.roll(left_q, -5, axis=1)
    right_q ^= (rng.random((n, n)) < 0.3).astype(np.uint8)  # noisy match: winners are not all exact zeros
    # float32 integral images of this pair are not exact
    diff0 = cv2.absdiff(left_q, right_q)
    f32 = cv2.integral(diff0, sdepth=cv2.CV_32F).astype(np.float64)
    i64 = cv2.integral(diff0, sdepth=cv2.CV_64F)
    assert np.abs(f32 - i64).max() >= 1.0
    res = sad_search(left_q, right_q, params)
    assert _engine((n, n), params).rolling == (mode == "rolling")
    # exact reference, streamed over the disparities (strict <: ties go to the smallest index, as in the engine)
    best = np.full((n, n), np.inf)
    index = np.full((n, n), -1)
    minus, plus = np.full((n, n), np.inf), np.full((n, n), np.inf)
    prev = np.full((n, n), np.inf)
    L, R = left_q.astype(np.int16), right_q.astype(np.int16)
    for i in range(n_disp):
        diff = np.zeros((n, n), np.int64)
        diff[:, i:] = np.abs(L[:, i:] - R[:, : n - i])
        cost = _exact_window_sums(diff, hw).astype(np.float64)
        cost[:, : i + hw] = np.inf  # the window must lie inside the right image
        plus = np.where(index == i - 1, cost, plus)
        new = cost < best
        minus = np.where(new, prev, minus)
        index, best = np.where(new, i, index), np.minimum(best, cost)
        prev = cost
    np.testing.assert_array_equal(res.index, index)
    np.testing.assert_array_equal(np.where(res.cost >= NO_MATCH, np.inf, res.cost), best)
    inner = (index > 0) & (index < n_disp - 1) & np.isfinite(minus) & np.isfinite(plus)
    assert inner.mean() > 0.9 and (index == 5).mean() > 0.9
    np.testing.assert_array_equal(res.cost_minus[inner], minus[inner])
    np.testing.assert_array_equal(res.cost_plus[inner], plus[inner])


def textured_pair(h_px: int, w_px: int, disparity_px: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A rendered-like textured pair (blurred noise), the right image shifted by ``disparity_px`` (sub-pixel)."""
    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (h_px, w_px + 64)).astype(np.float32), (0, 0), 1.2)
    tex = cv2.normalize(tex, None, 20, 235, cv2.NORM_MINMAX)
    xs = np.tile(np.arange(w_px, dtype=np.float32) + 32, (h_px, 1))
    ys = np.tile(np.arange(h_px, dtype=np.float32)[:, None], (1, w_px))
    left = cv2.remap(tex, xs, ys, cv2.INTER_CUBIC)
    right = cv2.remap(tex, xs + np.float32(disparity_px), ys, cv2.INTER_CUBIC)
    return np.clip(np.rint(left), 0, 255).astype(np.uint8), np.clip(np.rint(right), 0, 255).astype(np.uint8)


@pytest.mark.parametrize(("w_px", "h_px", "n_disp", "true_px"), [(741, 500, 64, 23.3), (1024, 1024, 128, 71.6)])
def test_rover_sim_stereo_runs_any_size(tmp_path, w_px: int, h_px: int, n_disp: int, true_px: float) -> None:  # noqa: ANN001
    from rover_sim.cli.main import app

    left, right = textured_pair(h_px, w_px, true_px)
    cv2.imwrite(str(tmp_path / "l.png"), left)
    cv2.imwrite(str(tmp_path / "r.png"), right)
    out = tmp_path / "d.npy"
    args = ["stereo", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--num-disparities", str(n_disp)]
    r = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert r.exit_code == 0, r.output
    d = np.load(out)
    assert d.shape == (h_px, w_px)
    inner = d[20:-20, n_disp + 20 : -20]
    assert np.isfinite(inner).mean() > 0.9
    assert np.nanmedian(np.abs(inner - true_px)) < 0.15


def test_too_large_image_names_the_limit() -> None:
    side = pipeline_mod.MAX_SIDE_PX + 1
    img = np.zeros((8, side), np.uint8)
    with pytest.raises(ValueError, match=f"{side}x8 px"):
        compute_disparity(img, img)


@pytest.mark.parametrize("mode", ["fused", "volume"])
def test_wide_rows_keep_the_disparity_tag_exact(monkeypatch: pytest.MonkeyPatch, mode: str) -> None:
    """On 1024 px rows the running row sums pass 2^16 while the window sums stay small (the OpenCV engine's float32
    path): every winner, its score and its neighbours' scores equal the exact integer reference (a fused key
    formation once rounded the disparity tag away there, giving ~5 % of the winners a neighbouring disparity)."""
    use_engine(monkeypatch, mode)
    h_px, w_px, hw, n_disp = 24, 1024, 3, 16
    params = StereoParams(num_disparities=n_disp, window_px=2 * hw + 1)
    rng = np.random.default_rng(21)
    left_q = rng.integers(0, 63, (h_px, w_px), dtype=np.uint8)
    right_q = np.roll(left_q, -6, axis=1)
    right_q ^= (rng.random((h_px, w_px)) < 0.4).astype(np.uint8)  # noisy: the winning scores are not zero
    assert not _engine((h_px, w_px), params).rolling
    res = sad_search(left_q, right_q, params)
    L, R = left_q.astype(np.int16), right_q.astype(np.int16)
    vol = np.full((n_disp, h_px, w_px), np.inf)
    for i in range(n_disp):
        diff = np.zeros((h_px, w_px), np.int64)
        diff[:, i:] = np.abs(L[:, i:] - R[:, : w_px - i])
        cost = _exact_window_sums(diff, hw).astype(np.float64)
        cost[:, : i + hw] = np.inf  # the window must lie inside the right image
        vol[i] = cost
    matched = np.isfinite(vol).any(axis=0)
    index = np.where(matched, np.argmin(np.where(np.isfinite(vol), vol, 1e9), axis=0), -1)
    np.testing.assert_array_equal(res.index, index)
    v, u = np.nonzero(matched)
    np.testing.assert_array_equal(res.cost[v, u], vol[index[v, u], v, u])
    assert (index[matched] == 6).mean() > 0.9
    if mode == "fused":
        return  # (integer keys: no tag to round)
    keys = _engine((h_px, w_px), params).costs  # every stored key carries its own disparity's tag
    for i in range(n_disp):
        k = keys[i][keys[i] < NO_MATCH]
        assert k.size > 0.5 * h_px * w_px
        np.testing.assert_array_equal((k - np.floor(k)) * 256, i)


def ground_like_pair(h_px: int, w_px: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Textured pair whose disparity grows down the rows (4 to 40 px, like the ground), with a featureless band."""
    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (h_px, w_px + 64)).astype(np.float32), (0, 0), 1.2)
    tex = cv2.normalize(tex, None, 20, 235, cv2.NORM_MINMAX)
    tex[h_px // 6 : h_px // 4] = 128.0  # no texture: these rows are not searched
    xs = np.tile(np.arange(w_px, dtype=np.float32) + 32, (h_px, 1))
    ys = np.tile(np.arange(h_px, dtype=np.float32)[:, None], (1, w_px))
    shift = np.linspace(4.0, 40.0, h_px, dtype=np.float32)[:, None]
    left = cv2.remap(tex, xs, ys, cv2.INTER_CUBIC)
    right = cv2.remap(tex, xs + shift, ys, cv2.INTER_CUBIC)
    return np.clip(np.rint(left), 0, 255).astype(np.uint8), np.clip(np.rint(right), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("shape", [(256, 256), (600, 560)])
def test_threads_do_not_change_the_disparity(
    engine_mode: str, shape: tuple[int, int], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The worker thread (from 512x512 px up: band-pass, texture and half of the search's rows) gives the same bits
    as the calling thread alone, on every call; the row split really runs where it should."""
    left, right = ground_like_pair(*shape)
    params = StereoParams(num_disparities=48, window_px=7)
    parts: list[int] = []
    search_rows = pipeline_mod._Pipeline.search_rows

    def spy(self, bands, v0, v1, part, *args):  # noqa: ANN001, ANN002, ANN202
        parts.append(part)
        return search_rows(self, bands, v0, v1, part, *args)

    monkeypatch.setattr(pipeline_mod._Pipeline, "search_rows", spy)
    n_threads = cv2.getNumThreads()
    try:
        cv2.setNumThreads(1)
        assert pipeline_mod.pipeline_threads(shape) == 1
        alone = compute_disparity(left, right, params)
        assert parts == [0]
        cv2.setNumThreads(2)
        threaded = pipeline_mod.pipeline_threads(shape) == 2
        assert threaded == (shape[0] * shape[1] >= 512 * 512)
        for _ in range(3):
            parts.clear()
            np.testing.assert_array_equal(compute_disparity(left, right, params), alone)
            split = threaded and engine_mode != "rolling"
            assert sorted(parts) == ([0, 1] if split else [0])
    finally:
        cv2.setNumThreads(n_threads)
    assert np.isfinite(alone).mean() > 0.5


def test_fused_key_is_exact_and_taken_where_row_sums_allow(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fused key (window sum and tag in one addWeighted) gives bit for bit the keys of the two-step key, and a
    256^2 search takes it on every stack (its row sums stay below ``FUSED_TAG_LIMIT``)."""
    scene = synth_pair(seed=3)
    taken: list[bool] = []
    stack_runs = sad_mod.Engine._stack_runs

    def spy(self, *args):  # noqa: ANN001, ANN202
        taken.append(stack_runs(self, *args))
        return taken[-1]

    monkeypatch.setattr(sad_mod.Engine, "_stack_runs", spy)
    use_engine(monkeypatch, "volume")
    fused = compute_disparity(scene.left, scene.right)
    assert taken and all(taken)
    monkeypatch.setattr(sad_mod, "FUSED_TAG_LIMIT", 0.0)
    monkeypatch.setattr(pipeline_mod._THREAD, "pipelines", {}, raising=False)
    taken.clear()
    two_step = compute_disparity(scene.left, scene.right)
    assert taken and not any(taken)
    np.testing.assert_array_equal(fused, two_step)
    assert np.isfinite(fused).mean() > 0.5


def test_small_images_run_opencv_on_one_thread_and_restore_it(monkeypatch: pytest.MonkeyPatch) -> None:
    """Below 512x512 the pipeline runs OpenCV single-threaded (a busy second core stalled its row-splitting calls);
    the caller's thread count is back afterwards, also when a call fails or calls nest."""
    pair = synth_pair(seed=1)
    left, right = pair.left, pair.right
    seen: list[int] = []
    run = pipeline_mod._Pipeline.run

    def spy(self, *args):  # noqa: ANN001, ANN002, ANN202
        seen.append(cv2.getNumThreads())
        if len(seen) == 2:
            raise RuntimeError("boom")
        if len(seen) == 3:  # a nested call (another thread's, say) restores nothing until the outer one leaves
            compute_disparity(left, right)
            seen.append(cv2.getNumThreads())
        return run(self, *args)

    monkeypatch.setattr(pipeline_mod._Pipeline, "run", spy)
    before = cv2.getNumThreads()
    try:
        cv2.setNumThreads(2)
        compute_disparity(left, right)
        assert cv2.getNumThreads() == 2
        with pytest.raises(RuntimeError, match="boom"):
            compute_disparity(left, right)
        assert cv2.getNumThreads() == 2
        compute_disparity(left, right)
        assert cv2.getNumThreads() == 2
        assert seen == [1, 1, 1, 1, 1]
    finally:
        cv2.setNumThreads(before)
