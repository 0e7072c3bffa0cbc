"""The compiled SAD engine (:mod:`nav.stereo.fused`) against the OpenCV engine (:class:`nav.stereo.sad.Engine`): the
same searched set and the same disparity maps, bit for bit, through the whole pipeline."""

from __future__ import annotations

import importlib
from dataclasses import replace

import cv2
import numpy as np
import pytest
from test_stereo import synth_pair
from test_stereo_sizes import ground_like_pair, textured_pair, use_engine

from nav.stereo import RowWindow, StereoParams, compute_disparity, sad_search
from nav.stereo.fused import MERGE_GAP_ROWS, searched_mask
from nav.stereo.sad import _row_bands

pipeline_mod = importlib.import_module("nav.stereo.pipeline")


def _bands_mask(window: RowWindow, n_disp: int) -> np.ndarray:
    """The OpenCV engine's plan (bands of rows per disparity) as an (H, D) mask."""
    mask = np.zeros((window.lo.size, n_disp), np.uint8)
    for i, runs in enumerate(_row_bands(window, n_disp, MERGE_GAP_ROWS)):
        for a, b in runs:
            mask[a:b, i] = 1
    return mask


@pytest.mark.parametrize("seed", range(6))
def test_searched_set_equals_the_opencv_engines_bands(seed: int) -> None:
    """Windows in segments of a few rows (as step 2 gives them), with unsearched rows and gaps shorter and longer
    than the merge gap: the compiled engine searches exactly the (row, disparity) set of the OpenCV engine."""
    rng = np.random.default_rng(seed)
    h_px, n_disp = 300, 48
    seg = np.repeat(np.arange(h_px // 4 + 1), 4)[:h_px]
    lo = rng.integers(0, 30, seg.max() + 1)[seg].astype(np.int32)
    hi = (lo + rng.integers(0, 14, seg.max() + 1)[seg]).astype(np.int32)
    np.minimum(hi, n_disp - 1, out=hi)
    for start, length in ((20, 12), (100, 41), (180, 40), (250, 3)):
        hi[start : start + length] = -1  # not searched: some gaps merge, some do not
    window = RowWindow(lo, hi)
    got = np.empty((h_px, n_disp), np.uint8)
    searched_mask(window.lo, window.hi, n_disp, MERGE_GAP_ROWS, got)
    expected = _bands_mask(window, n_disp)
    assert expected.sum() > 0.1 * expected.size
    merged = expected.astype(bool) & ~((lo[:, None] <= np.arange(n_disp)) & (np.arange(n_disp) <= hi[:, None]))
    assert merged.any()  # some rows are searched outside their own window (merged bands)
    np.testing.assert_array_equal(got, expected)


def _pairs() -> list[tuple[str, np.ndarray, np.ndarray, StereoParams]]:
    base = StereoParams(num_disparities=32)
    scene = synth_pair(seed=5)
    ground = ground_like_pair(256, 256, seed=2)
    wide = textured_pair(120, 741, 23.3, seed=4)
    return [
        ("scene", scene.left, scene.right, StereoParams()),
        ("scene/32", scene.left, scene.right, base),
        ("scene/min8", scene.left, scene.right, replace(base, min_disparity=8)),
        ("scene/no-row-window", scene.left, scene.right, replace(base, row_window=False)),
        ("ground/w7", *ground, StereoParams(num_disparities=48, window_px=7)),
        ("ground/w21", *ground, StereoParams(num_disparities=48, window_px=21)),
        ("741x120", *wide, StereoParams(num_disparities=64)),
    ]


@pytest.mark.parametrize("case", _pairs(), ids=lambda c: c[0])
def test_engines_give_the_same_disparity(monkeypatch: pytest.MonkeyPatch, case: tuple) -> None:
    _, left, right, params = case
    use_engine(monkeypatch, "volume")
    ref = compute_disparity(left, right, params)
    assert np.isfinite(ref).mean() > 0.2  # (not a vacuous comparison)
    use_engine(monkeypatch, "fused")
    got = compute_disparity(left, right, params)
    np.testing.assert_array_equal(got, ref)
    assert isinstance(pipeline_mod._pipeline(left.shape, params).engine, pipeline_mod.FusedEngine)


def test_engines_agree_on_threaded_rows(monkeypatch: pytest.MonkeyPatch) -> None:
    """From 512x512 px up the search's rows are split between two threads: the compiled kernel runs in both at once
    (it releases the GIL) and gives the OpenCV engine's bits."""
    left, right = ground_like_pair(600, 560, seed=1)
    params = StereoParams(num_disparities=48, window_px=7)
    n_threads = cv2.getNumThreads()
    try:
        cv2.setNumThreads(2)
        assert pipeline_mod.pipeline_threads(left.shape) == 2
        use_engine(monkeypatch, "volume")
        ref = compute_disparity(left, right, params)
        use_engine(monkeypatch, "fused")
        for _ in range(3):
            np.testing.assert_array_equal(compute_disparity(left, right, params), ref)
    finally:
        cv2.setNumThreads(n_threads)


def test_sad_search_outputs_agree_where_the_checks_read_them(monkeypatch: pytest.MonkeyPatch) -> None:
    """Winners, scores and right winners are identical; neighbour scores too wherever the winner lies strictly
    inside its row's window (elsewhere the OpenCV engine may read an earlier search's key, the compiled one reads
    ``NO_MATCH``: the edge check rejects both)."""
    from nav.stereo import bandpass, quantise, row_search_window

    scene = synth_pair(seed=2)
    params = StereoParams(num_disparities=32)
    bp_l, bp_r = bandpass(scene.left, params), bandpass(scene.right, params)
    window = row_search_window(bp_l, bp_r, params)
    q_l, q_r = quantise(bp_l, params), quantise(bp_r, params)
    use_engine(monkeypatch, "volume")
    sad_search(q_r, q_l, params)  # an earlier search leaves other keys in the volume
    ref = sad_search(q_l, q_r, params, window)
    use_engine(monkeypatch, "fused")
    got = sad_search(q_l, q_r, params, window)
    for name in ("index", "cost", "second_cost", "right_index"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    inside = (ref.index > window.lo[:, None]) & (ref.index < window.hi[:, None])
    assert inside.mean() > 0.5
    for name in ("cost_minus", "cost_plus"):
        np.testing.assert_array_equal(getattr(got, name)[inside], getattr(ref, name)[inside], err_msg=name)


def test_engine_choice_is_checked(monkeypatch: pytest.MonkeyPatch) -> None:
    """A typo in NAV_STEREO_ENGINE, or the compiled engine without numba, is a one-line error naming the variable."""
    pair = synth_pair(seed=1)
    left, right = pair.left, pair.right
    monkeypatch.setattr(pipeline_mod._THREAD, "pipelines", {}, raising=False)
    monkeypatch.setattr(pipeline_mod, "SAD_ENGINE", "fast")
    typo = r"SAD engine 'fast' \(NAV_STEREO_ENGINE or engine=\): use 'fused' or 'opencv'"
    with pytest.raises(ValueError, match=typo):
        compute_disparity(left, right)
    monkeypatch.setattr(pipeline_mod, "SAD_ENGINE", "fused")
    monkeypatch.setattr(pipeline_mod, "FusedEngine", None)
    with pytest.raises(ValueError, match="needs numba.*NAV_STEREO_ENGINE=opencv"):
        compute_disparity(left, right)
    monkeypatch.setattr(pipeline_mod, "SAD_ENGINE", "opencv")
    assert pipeline_mod.sad_engine() == "opencv"
    assert np.isfinite(compute_disparity(left, right)).mean() > 0.5


def test_engine_argument_picks_the_engine_per_call() -> None:
    """``compute_disparity(..., engine=)`` runs the named engine whatever ``NAV_STEREO_ENGINE`` says (each keeps its
    own cached pipeline), with the same result; an unknown name is refused."""
    pair = synth_pair(seed=4)
    fused = compute_disparity(pair.left, pair.right, engine="fused")
    opencv = compute_disparity(pair.left, pair.right, engine="opencv")
    np.testing.assert_array_equal(fused, opencv)
    assert np.isfinite(fused).mean() > 0.5
    params = StereoParams()
    assert isinstance(pipeline_mod._pipeline(pair.left.shape, params, "opencv").engine, pipeline_mod.Engine)
    assert isinstance(pipeline_mod._pipeline(pair.left.shape, params, "fused").engine, pipeline_mod.FusedEngine)
    with pytest.raises(ValueError, match="SAD engine 'cuda'.*use 'fused' or 'opencv'"):
        compute_disparity(pair.left, pair.right, engine="cuda")
