"""The MER stereo pipeline (Maimone et al. 2005, section 4.1) run end to end: :func:`compute_disparity` (steps
1-6 in order, on buffers kept between calls), the step functions that run on the same cached pipeline
(:func:`row_search_window`, step 2; :func:`sad_search`, step 3), the paper's "XYZ range images"
(:func:`range_image`) and the OpenCV StereoBM baseline.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import Future, ThreadPoolExecutor

import cv2
import numpy as np

from nav.camera import PinholeCamera, StereoRig
from nav.stereo.bandpass import bandpass_into, quantise_gain, quantise_into, texture_into
from nav.stereo.checks import discontinuity, left_right, sad_limit, speckle_filter, uniqueness
from nav.stereo.params import RangeImage, RowWindow, SadSearch, StereoParams
from nav.stereo.sad import Engine, subpixel

try:  # the compiled SAD search (numba); without it the OpenCV engine runs, with the same results
    from nav.stereo.fused import FusedEngine
except ImportError:  # pragma: no cover - numba is a dependency of the rover-sim package
    FusedEngine = None

MAX_SIDE_PX = 4096  # images up to this side (larger ones: bin them; the SAD engine's buffers grow as H * W)
# A parabola curvature (SAD units) this large means a neighbour's score was NO_MATCH (not searched).
_CURVATURE_LIMIT = float(2**19)
_COARSE_SCALE = 4  # row_search_window matches the images binned 4x4 (two pyrDown)
_COARSE_MIN_VOTES = 8  # a disparity must be found this many times near a row to enter its search window
_NONE_INDEX = -3.0  # the coarse right index where a right pixel has no winner (fails a 1 px left-right test)
# The SAD engine: "fused" (nav.stereo.fused, compiled with numba) or "opencv" (nav.stereo.sad.Engine, OpenCV calls
# only). Both give the same disparities bit for bit; with the fused one a 256^2 call takes about 0.7 of the time
# (bench stereo: 1.3 against 1.9 ms), barely slows with the other core's memory traffic, and keeps no SAD volume. Set
# NAV_STEREO_ENGINE=opencv to run nav's stereo with numpy, scipy and OpenCV alone.
SAD_ENGINE = os.environ.get("NAV_STEREO_ENGINE", "fused" if FusedEngine is not None else "opencv")


# ----------------------------------------------------------------------------------------------------------------
# Step 2: the disparity window of each row
# ----------------------------------------------------------------------------------------------------------------


def row_search_window(bp_left: np.ndarray, bp_right: np.ndarray, params: StereoParams = StereoParams()) -> RowWindow:
    """Step 2: the disparity indices to search on each row, from a full-range search at quarter resolution.

    Both band-passed images are binned 4x4 (``cv2.pyrDown`` twice), quantised and matched over the whole range with
    the same engine (a 5 px window there, 20 px of the image). Matches that pass the left-right, uniqueness (over the
    whole range: the full-resolution search sees only the row's window) and texture checks vote for their sub-pixel
    disparity times 4. A row's window spans the disparities with at least ``_COARSE_MIN_VOTES`` votes on the coarse
    rows its SAD window touches, widened by ``row_window_margin_px`` on both sides. Rows without votes are not searched
    (the sky, featureless ground). Everything then happens on the rows from the first to the last searched one.
    """
    bp_left, bp_right = np.asarray(bp_left, np.float32), np.asarray(bp_right, np.float32)
    return _pipeline(bp_left.shape, params).row_window(bp_left, bp_right)


# ----------------------------------------------------------------------------------------------------------------
# Step 3: SAD search
# ----------------------------------------------------------------------------------------------------------------


def sad_search(
    left_q: np.ndarray, right_q: np.ndarray, params: StereoParams = StereoParams(), window: RowWindow | None = None
) -> SadSearch:
    """Step 3 (paper: "area-based algorithm using the sum of absolute differences (SAD) criterion").

    For every disparity ``s`` the window SAD between the left image and the right image shifted by ``s`` is formed
    from an integral image of ``|L(u) - R(u - s)|`` over the rows whose ``window`` contains it (all rows if
    ``window`` is None). The window is clipped at the top, bottom and right borders (the same pixels for every
    disparity) and must lie inside the right image on the left. Each score is stored as
    ``key = SAD + index / 256``. The running minimum of the keys over the left pixels gives the left winner; the
    running minimum over the *right* pixels ``u_right = u - s`` gives the right-referenced winner (the same scores,
    so exactly the disparity a search from the right image would find). Per disparity class ``index mod 3`` the
    best key is kept, and the least of the classes' second-best keys: the best score more than 1 px from the winner
    is then the best of three candidates (a class holds at most one neighbour of the winner), so the uniqueness
    test is exact without a second pass.
    """
    left_q, right_q = _as_pair(left_q, right_q)
    _check_size(left_q.shape, params)
    engine = _pipeline(left_q.shape, params).engine
    np.copyto(engine.left_q, left_q)
    np.copyto(engine.right_q, right_q)
    engine.search(window)
    engine.forget_stacks()  # (the caller's images may exceed the quantised range the stack's exactness assumes)
    index, right_index = engine.winners()
    cost, cost_minus, cost_plus, second = engine.scores(index)
    found = engine.found()
    return SadSearch(
        np.where(found, index, -1).astype(np.int32),
        cost.copy(),
        cost_minus.copy(),
        cost_plus.copy(),
        second.copy(),
        right_index.astype(np.int32),
        engine.window,
    )


# ----------------------------------------------------------------------------------------------------------------
# The pipeline
# ----------------------------------------------------------------------------------------------------------------


def compute_disparity(
    left_u8: np.ndarray, right_u8: np.ndarray, params: StereoParams = StereoParams(), engine: str | None = None
) -> np.ndarray:
    """Left-referenced disparity (px, float32, NaN where invalid) of a rectified 8-bit pair, MER style.

    ``engine``: the SAD search, "fused" (compiled) or "opencv"; None: :func:`sad_engine` (``NAV_STEREO_ENGINE``).
    Both give the same result bit for bit."""
    left_u8, right_u8 = _as_pair(left_u8, right_u8)
    _check_size(left_u8.shape, params)
    pipe = _pipeline(left_u8.shape, params, engine)
    if pipeline_threads(left_u8.shape) > 1:
        return pipe.run(left_u8, right_u8)
    with _serial_opencv():
        return pipe.run(left_u8, right_u8)


def _check_size(shape: tuple[int, int], params: StereoParams) -> None:
    """Any size up to ``MAX_SIDE_PX`` on a side: the SAD sums are exact at every size (see :class:`Engine`)."""
    if max(shape) > MAX_SIDE_PX:
        raise ValueError(
            f"image {shape[1]}x{shape[0]} px: sides up to {MAX_SIDE_PX} px are supported; bin it (MER used 256x256)"
        )


class _Pipeline:
    """:func:`compute_disparity` for one image shape and parameter set, with every buffer it needs."""

    def __init__(self, shape: tuple[int, int], params: StereoParams, engine: str) -> None:
        self.shape, self.params = shape, params
        cap2 = 2 * params.quantise_cap
        engine_class = _engine_class(engine)
        self.engine = engine_class(shape, params.min_disparity, params.num_disparities, params.window_px, cap2)
        f32, u8 = (lambda s=shape: np.empty(s, np.float32)), (lambda s=shape: np.empty(s, np.uint8))
        self.bp_left, self.bp_right, self.scratch, self.scratch2, self.scratch3, self.curvature, self.offset = (
            f32() for _ in range(7)
        )
        self.scratch_right = f32()  # (the right image's band-pass runs beside the left one's)
        self.ok, self.ok2, self.ok3, self.ok2x, self.ok4 = (u8() for _ in range(5))
        self.lo, self.hi = f32(), f32()
        self.lo_col, self.hi_col = np.empty((shape[0], 1), np.float32), np.empty((shape[0], 1), np.float32)
        self.fixed, self.fixed2 = np.empty(shape, np.int16), np.empty(shape, np.int16)
        self.nan = np.full(shape, np.nan, np.float32)
        self.minus16 = np.full(shape, -16, np.int16)
        # coarse search (row windows)
        f = _COARSE_SCALE
        self.coarse = None
        if params.row_window and min(shape) >= 8 * f:
            shape_c = shape
            while shape_c[0] > (shape[0] + f - 1) // f:
                shape_c = ((shape_c[0] + 1) // 2, (shape_c[1] + 1) // 2)
            self.min_c = params.min_disparity // f
            self.n_c = -(-(params.min_disparity + params.num_disparities) // f) - self.min_c + 1
            self.window_c = max(5, (params.window_px // 2) | 1)  # at 1/4 scale: 20 px or more of the image
            self.coarse = engine_class(shape_c, self.min_c, self.n_c, self.window_c, cap2)
            f32c, u8c = (lambda: np.empty(shape_c, np.float32)), (lambda: np.empty(shape_c, np.uint8))
            self.left_c, self.right_c, self.scratch_c, self.scratch_c2, self.curvature_c, self.offset_c = (
                f32c() for _ in range(6)
            )
            self.ok_c, self.ok_c2 = u8c(), u8c()
            self.bins = np.empty(shape_c, np.int32)
            n_bins = params.num_disparities + 2
            # the coarse rows a full-resolution row's SAD window touches
            v, hw = np.arange(shape[0]), params.half_window_px
            vote_lo = np.clip((v - hw) // f, 0, shape_c[0])
            vote_hi = np.clip((v + hw) // f + 1, 0, shape_c[0])
            # (rows share these ranges about f at a time: the votes are counted once per distinct range)
            pairs, self.vote_row = np.unique(np.stack([vote_lo, vote_hi], axis=1), axis=0, return_inverse=True)
            self.vote_row = self.vote_row.reshape(-1)
            self.vote_lo, self.vote_hi = pairs[:, 0], pairs[:, 1]
            self.row_bins = np.repeat((np.arange(shape_c[0], dtype=np.int32) * n_bins)[:, None], shape_c[1], axis=1)
            self.cum = np.zeros((shape_c[0] + 1, n_bins), np.int64)

    def row_window(self, bp_left: np.ndarray, bp_right: np.ndarray) -> RowWindow:
        params, h_px = self.params, self.shape[0]
        if self.coarse is None:
            return RowWindow.full(h_px, params.num_disparities)
        left_c, right_c = bp_left, bp_right
        while left_c.shape != self.coarse.shape:
            last = (
                left_c.shape == (self.coarse.shape[0] * 2, self.coarse.shape[1] * 2)
                or ((left_c.shape[0] + 1) // 2, (left_c.shape[1] + 1) // 2) == self.coarse.shape
            )
            left_c = cv2.pyrDown(left_c, dst=self.left_c if last else None)
            right_c = cv2.pyrDown(right_c, dst=self.right_c if last else None)
        window_c, coarse = self.window_c, self.coarse
        quantise_into(left_c, params, coarse.left_q)
        quantise_into(right_c, params, coarse.right_q)
        coarse.search(None)
        index, right_index = coarse.winners(none_index=_NONE_INDEX)
        ok = left_right(index, right_index, 1, 0, self.ok_c, self.scratch_c, self.scratch_c2, self.ok_c2, _NONE_INDEX)
        # uniqueness over the whole range (the full-resolution search sees only the row's window)
        cost, cost_minus, cost_plus, second = coarse.scores(index)
        subpixel(cost_minus, cost, cost_plus, self.curvature_c, self.offset_c)
        uniq = uniqueness(cost, second, self.curvature_c, params.uniqueness_ratio, self.ok_c2, self.scratch_c)
        cv2.bitwise_and(ok, uniq, dst=ok)
        cv2.bitwise_and(
            ok, texture_into(left_c, params.texture_threshold, window_c, self.ok_c2, self.scratch_c), dst=ok
        )
        # votes per (coarse row, full-resolution disparity index + 1): the coarse sub-pixel disparity times the
        # scale; pixels that fail vote for bin 0, which is not counted
        f, n_bins = _COARSE_SCALE, params.num_disparities + 2
        bins = cv2.addWeighted(
            index, f, self.offset_c, f, f * self.min_c - params.min_disparity + 1.0, dst=self.bins, dtype=cv2.CV_32S
        )
        cv2.min(cv2.max(bins, 1, dst=bins), n_bins - 1, dst=bins)
        cv2.add(bins, self.row_bins, dst=bins)  # the coarse row's histogram
        cv2.copyTo(self.row_bins, cv2.bitwise_not(ok, dst=ok), bins)  # its bin 0
        h_c = coarse.shape[0]
        cum = self.cum
        np.cumsum(np.bincount(bins.ravel(), minlength=h_c * n_bins).reshape(h_c, n_bins), axis=0, out=cum[1:])
        found = (cum[self.vote_hi] - cum[self.vote_lo]) >= _COARSE_MIN_VOTES  # (ranges, bins): disparities near
        found[:, 0] = False
        d_max = params.num_disparities - 1
        first = np.argmax(found, axis=1)  # 0 where nothing matched near the rows (bin 0 is never found)
        lo = first - (1 + params.row_window_margin_px)  # bin b holds index b - 1
        hi = (n_bins - 2 + params.row_window_margin_px) - np.argmax(found[:, ::-1], axis=1)
        np.maximum(lo, 0, out=lo)
        np.minimum(hi, d_max, out=hi)
        hi[first == 0] = -1  # nothing matched near these rows: not searched
        np.minimum(lo, d_max, out=lo)
        return RowWindow(lo.astype(np.int32)[self.vote_row], hi.astype(np.int32)[self.vote_row])

    def run(self, left_u8: np.ndarray, right_u8: np.ndarray) -> np.ndarray:
        params, h_px = self.params, self.shape[0]
        pool = _worker_pool(self.shape)
        if pool is None:
            bp_left = bandpass_into(left_u8, params, self.bp_left, self.scratch)  # 1. band-pass
        else:  # the left image in the worker, the right one here
            job = pool.submit(bandpass_into, left_u8, params, self.bp_left, self.scratch)
        try:
            bp_right = bandpass_into(right_u8, params, self.bp_right, self.scratch_right)
        finally:
            if pool is not None:
                bp_left = job.result()
        window = self.row_window(bp_left, bp_right)  # 2. row windows
        searched = np.nonzero(window.lo <= window.hi)[0]
        disparity = np.empty(self.shape, np.float32)  # the result: a fresh array
        if searched.size == 0:
            disparity.fill(np.nan)
            return disparity
        v0, v1 = int(searched[0]), int(searched[-1]) + 1  # everything below works on these rows only
        disparity[:v0].fill(np.nan)
        disparity[v1:].fill(np.nan)
        rows = slice(v0, v1)
        engine = self.engine  # 3. SAD
        gain_left = quantise_gain(bp_left, params)
        quantise_into(bp_left, params, engine.left_q, gain_left)
        quantise_into(bp_right, params, engine.right_q)
        hw = params.half_window_px  # texture: the band-passed rows with half a window more on each side
        t0, t1 = max(v0 - hw, 0), min(v1 + hw, h_px)
        texture_args = (bp_left[t0:t1], params.texture_threshold, params.window_px, self.ok4[t0:t1])
        texture_args += (self.scratch3[t0:t1],)
        # (with a worker: the texture there while the search runs here; the checks wait for it)
        texture = texture_into(*texture_args) if pool is None else pool.submit(texture_into, *texture_args)
        bands = engine.plan(window)
        parts = _split_rows(window, v0, v1, 2 if pool is not None and not engine.rolling else 1)
        try:
            if len(parts) == 1:
                self.search_rows(bands, v0, v1, 0, gain_left, disparity, texture)
            else:  # 3-5 on the rows' top part in the worker, the bottom part here (disjoint rows of every buffer)
                part0 = engine.clip(bands, *parts[0])
                job = pool.submit(self.search_rows, part0, *parts[0], 0, gain_left, disparity, texture)
                try:
                    self.search_rows(engine.clip(bands, *parts[1]), *parts[1], 1, gain_left, disparity, texture)
                finally:
                    job.result()
        finally:
            if isinstance(texture, Future):
                texture.result()
        ok, tmp, tmp2, bad = self.ok[rows], self.ok2[rows], self.ok2x[rows], self.ok3[rows]
        out = disparity[rows]
        if params.discontinuity_px > 0 or params.speckle_window_size > 0:
            fixed = self.fixed[rows]
        if params.discontinuity_px > 0:
            keep = discontinuity(fixed, bad, params.discontinuity_px, hw, tmp, tmp2, self.fixed2[rows])
            cv2.bitwise_not(cv2.bitwise_and(ok, keep, dst=ok), dst=bad)
        if params.speckle_window_size > 0:  # 6. blob filter
            cv2.copyTo(self.minus16[rows], bad, fixed)
            # afterwards -16 marks exactly the pixels failed so far and the removed blobs (a valid disparity is
            # >= 0.5 px: the winner lies strictly inside its window, index >= 1, and |sub-pixel offset| <= 0.5)
            speckle_filter(fixed, params)
            cv2.compare(fixed, -16, cv2.CMP_EQ, bad)
        cv2.copyTo(self.nan[rows], bad, out)
        return disparity

    def search_rows(
        self,
        bands: list,
        v0: int,
        v1: int,
        part: int,
        gain_left: float,
        disparity: np.ndarray,
        texture: Future | np.ndarray,
    ) -> None:
        """Steps 3-5 on rows ``v0:v1`` (row-local: parts of the rows may run in concurrent threads; ``texture``: the
        texture check's job, waited for before its result is read). Leaves the disparity there, ``ok``/``bad`` (the
        checks passed/failed) and, if a later filter needs it, ``fixed``."""
        params, engine = self.params, self.engine
        engine.search_rows(bands, v0, v1, part)
        none_index = -float(params.lr_max_diff_px + 2)  # (fails the left-right test by itself)
        index, right_index = engine.winners(v0, v1, none_index)
        rows = slice(v0, v1)
        cost, cost_minus, cost_plus, second = engine.scores(index, rows)
        curvature, offset = self.curvature[rows], self.offset[rows]
        subpixel(cost_minus, cost, cost_plus, curvature, offset)  # 4. sub-pixel
        # 5. checks. Edge: lo < index < hi, and both neighbours' scores exist (else the curvature is huge)
        ok, tmp, tmp2, bad = self.ok[rows], self.ok2[rows], self.ok2x[rows], self.ok3[rows]
        scratch, scratch2 = self.scratch[rows], self.scratch2[rows]
        lo, hi, window = self.lo[rows], self.hi[rows], engine.window
        # indices and curvatures are integers: lo + 1 <= index <= hi - 1 (per-row bounds: float32 columns broadcast;
        # two compares: inRange with array bounds takes twice as long)
        np.copyto(lo, np.add(window.lo[rows, None], 1, out=self.lo_col[rows], casting="unsafe"))
        np.copyto(hi, np.subtract(window.hi[rows, None], 1, out=self.hi_col[rows], casting="unsafe"))
        cv2.bitwise_and(cv2.compare(index, lo, cv2.CMP_GE, ok), cv2.compare(index, hi, cv2.CMP_LE, tmp), ok)
        cv2.bitwise_and(ok, cv2.inRange(curvature, 1.0, _CURVATURE_LIMIT - 1.0, dst=tmp), dst=ok)
        if isinstance(texture, Future):
            texture.result()
        cv2.bitwise_and(ok, self.ok4[rows], dst=ok)  # texture (run has filled it on these rows)
        if params.max_sad_ratio > 0:  # match quality, from the texture's local mean square
            limit = sad_limit(self.scratch3[rows], params, gain_left, scratch)
            cv2.bitwise_and(ok, cv2.compare(cost, limit, cv2.CMP_LE, dst=tmp), dst=ok)
        cv2.bitwise_and(ok, uniqueness(cost, second, curvature, params.uniqueness_ratio, tmp, scratch), dst=ok)
        cv2.bitwise_and(
            ok, left_right(index, right_index, params.lr_max_diff_px, 0, tmp, scratch, scratch2, tmp2, none_index), ok
        )
        out = disparity[rows]
        cv2.add(index, offset, dst=out)
        if params.min_disparity:
            cv2.add(out, float(params.min_disparity), dst=out)
        cv2.bitwise_not(ok, dst=bad)
        if params.discontinuity_px > 0 or params.speckle_window_size > 0:
            cv2.addWeighted(out, 16.0, out, 0.0, 0.0, dst=self.fixed[rows], dtype=cv2.CV_16S)  # 1/16 px


def sad_engine() -> str:
    """The SAD engine :func:`compute_disparity` runs: "fused" (compiled) or "opencv" (``NAV_STEREO_ENGINE``)."""
    return SAD_ENGINE


def _engine_class(name: str) -> type:
    """The SAD engine class ``name`` names (checked: a typo in ``NAV_STEREO_ENGINE`` is an error, not a silent
    fallback)."""
    if name == "fused":
        if FusedEngine is None:
            raise ValueError("NAV_STEREO_ENGINE=fused needs numba (pip install numba), or set NAV_STEREO_ENGINE=opencv")
        return FusedEngine
    if name == "opencv":
        return Engine
    raise ValueError(f"SAD engine {name!r} (NAV_STEREO_ENGINE or engine=): use 'fused' or 'opencv'")


def _split_rows(window: RowWindow, v0: int, v1: int, n_parts: int) -> list[tuple[int, int]]:
    """``v0:v1`` cut into ``n_parts`` row ranges of about equal work: a row costs its searched disparities plus
    about ``_POST_ROW_COST`` more for the steps after the search. Ranges shorter than ``_MIN_PART_ROWS``: one."""
    if n_parts < 2 or v1 - v0 < 2 * _MIN_PART_ROWS:
        return [(v0, v1)]
    work = np.maximum(window.hi[v0:v1] - window.lo[v0:v1] + 1, 0) + _POST_ROW_COST
    cum = np.cumsum(work)
    cut = v0 + int(np.searchsorted(cum, cum[-1] / 2))
    cut = min(max(cut, v0 + _MIN_PART_ROWS), v1 - _MIN_PART_ROWS)
    return [(v0, cut), (cut, v1)]


def pipeline_threads(shape: tuple[int, int]) -> int:
    """Threads :func:`compute_disparity` runs on for images of ``shape``: 2 (the caller's and one worker's) from
    ``_THREADED_MIN_PX`` pixels up where OpenCV may use two or more (``cv2.getNumThreads()``), else 1. The worker
    band-passes the left image beside the right one, runs the texture check beside the search and takes half of the
    search's rows (steps 3-5; the rolling search keeps all rows on one thread)."""
    return 2 if cv2.getNumThreads() >= 2 and shape[0] * shape[1] >= _THREADED_MIN_PX else 1


def _worker_pool(shape: tuple[int, int]) -> ThreadPoolExecutor | None:
    """The one worker thread beside the caller's (created once), or None where the pipeline runs entirely on the
    calling thread (see :func:`pipeline_threads`)."""
    if pipeline_threads(shape) < 2:
        return None
    with _POOL_LOCK:
        if not _POOL:
            _POOL.append(ThreadPoolExecutor(max_workers=1, thread_name_prefix="nav-stereo"))
        return _POOL[0]


# Smaller images run on the calling thread alone: at 256x256 a call is many OpenCV calls of a few microseconds each
# (~700 with the OpenCV SAD engine, where this was measured), and a worker taking turns with it at the GIL cost more
# than it saved (bench stereo pairs, shared 2-core machine, load 2-3: 10-15 % slower with the rows split, 1-6 % with
# only the band-pass and texture beside; StereoBM gained nothing from its second thread there either); at 1024x1024
# the calls are long and the two threads overlap.
_THREADED_MIN_PX = 512 * 512
_POST_ROW_COST = 8  # steps 3-5 after the search cost about as much per row as this many disparities
_MIN_PART_ROWS = 16
_POOL: list[ThreadPoolExecutor] = []  # the worker pool, once created
_POOL_LOCK = threading.Lock()
os.register_at_fork(after_in_child=_POOL.clear)  # (a forked child has no worker thread: it makes its own)


class _serial_opencv:
    """OpenCV on the calling thread only (``cv2.setNumThreads(1)``) while a single-threaded pipeline runs, restored
    when the last such call in the process leaves (calls may nest or overlap in several threads).

    At 256x256 a call is many OpenCV calls of a few microseconds (~700 with the OpenCV SAD engine); a few of them
    (``pyrDown``, ``pyrUp``) split their rows with OpenCV's worker threads and then wait for them. When the second
    core is busy the worker is not scheduled in time and the caller waits: with a memory-streaming process on the
    other core of this 2-core machine a 256^2 ``bench stereo`` call took 7.4 ms with OpenCV's two threads and
    2.6-3.2 ms with one; on a quiet machine the two take the same time. StereoBM runs one stripe at this size (OpenCV
    sizes its stripes to ~8M SAD terms).
    Other threads' OpenCV calls during such a call run on one thread too.
    """

    def __enter__(self) -> None:
        with _SERIAL_LOCK:
            if _SERIAL_STATE[0] == 0:
                _SERIAL_STATE[1] = cv2.getNumThreads()
                if _SERIAL_STATE[1] > 1:
                    cv2.setNumThreads(1)
            _SERIAL_STATE[0] += 1

    def __exit__(self, *exc: object) -> None:
        with _SERIAL_LOCK:
            _SERIAL_STATE[0] -= 1
            if _SERIAL_STATE[0] == 0 and _SERIAL_STATE[1] > 1:
                cv2.setNumThreads(_SERIAL_STATE[1])


_SERIAL_LOCK = threading.Lock()
_SERIAL_STATE = [0, 0]  # [calls inside, OpenCV's thread count before the first of them entered]

_THREAD = threading.local()


def _pipeline(shape: tuple[int, int], params: StereoParams, engine: str | None = None) -> _Pipeline:
    """The calling thread's pipeline for this shape, parameter set and SAD engine (two are kept: its buffers take
    about 100 bytes per pixel, plus, with the OpenCV engine, a SAD volume of up to ``VOLUME_BUDGET_BYTES``)."""
    cache = getattr(_THREAD, "pipelines", None)
    if cache is None:
        cache = _THREAD.pipelines = {}
    engine = SAD_ENGINE if engine is None else engine
    key = (tuple(shape), params, engine)
    pipe = cache.get(key)
    if pipe is None:
        if len(cache) >= 2:
            cache.pop(next(iter(cache)))
        pipe = cache[key] = _Pipeline(tuple(shape), params, engine)
    return pipe


def _as_pair(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    left, right = np.asarray(left), np.asarray(right)
    if left.shape != right.shape or left.ndim != 2:
        raise ValueError(f"need two greyscale images of one shape, got {left.shape} and {right.shape}")
    if left.dtype != np.uint8 or right.dtype != np.uint8:
        raise ValueError("images must be uint8 (8-bit greyscale); convert with np.clip(img, 0, 255).astype(np.uint8)")
    return np.ascontiguousarray(left), np.ascontiguousarray(right)


# ----------------------------------------------------------------------------------------------------------------
# XYZ range images
# ----------------------------------------------------------------------------------------------------------------


def disparity_to_xyz_cam(disparity_px: np.ndarray, rig: StereoRig) -> np.ndarray:
    """(H, W, 3) left-camera-frame points of a disparity image; NaN where the disparity is NaN or not positive."""
    d = np.asarray(disparity_px, dtype=np.float64)
    cam = rig.left
    z = rig.depth_from_disparity(d)
    v, u = np.indices(d.shape, dtype=np.float64)
    x = (u - cam.cx_px) / cam.fx_px * z
    y = (v - cam.cy_px) / cam.fy_px * z
    return np.stack([x, y, z], axis=-1)


def xyz_cam_to_rover(xyz_cam: np.ndarray, cam: PinholeCamera) -> np.ndarray:
    """Map (..., 3) camera-frame points to the rover frame with ``cam.T_rover_cam``; NaN points stay NaN."""
    T = np.asarray(cam.T_rover_cam, dtype=np.float64)
    return np.asarray(xyz_cam, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]


def range_image(
    left_u8: np.ndarray, right_u8: np.ndarray, rig: StereoRig, params: StereoParams = StereoParams()
) -> RangeImage:
    """Disparity, camera- and rover-frame XYZ of a rectified pair (the paper's "XYZ range images")."""
    disparity = compute_disparity(left_u8, right_u8, params)
    xyz_cam = disparity_to_xyz_cam(disparity, rig)
    valid = np.isfinite(xyz_cam[..., 2])
    return RangeImage(disparity, xyz_cam, xyz_cam_to_rover(xyz_cam, rig.left), valid)


def stereobm_baseline(
    left_u8: np.ndarray, right_u8: np.ndarray, num_disparities: int = 64, window_px: int = 9
) -> np.ndarray:
    """Plain OpenCV StereoBM (default checks), float32 px with NaN where invalid: the benchmark reference."""
    left_u8, right_u8 = _as_pair(left_u8, right_u8)
    bm = cv2.StereoBM_create(numDisparities=num_disparities, blockSize=window_px)
    raw = bm.compute(left_u8, right_u8)
    disparity = raw.astype(np.float32) / 16.0
    disparity[raw < 0] = np.nan  # StereoBM marks invalid pixels with (min_disparity - 1) * 16 = -16
    return disparity
