"""Steps 3-4 of the MER stereo pipeline (Maimone et al. 2005, section 4.1): the "area-based algorithm using the
sum of absolute differences (SAD) criterion" (:class:`Engine`, one pass over the disparities) and the
"subpixel disparities [...] computed by quadratic interpolation of SAD scores".

The public step function :func:`nav.stereo.sad_search` runs the engine held by the cached pipeline (its
buffers are shared with :func:`nav.stereo.compute_disparity`), so it lives in :mod:`nav.stereo.pipeline`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from nav.stereo.params import NO_MATCH, TAG, RowWindow

# Above this size the SAD volume (num_disparities * H * W float32) is not kept: the scores beside each pixel's running
# winner are carried along instead. 768 MiB keeps full 1024^2 searches (128 disparities: 512 MiB) and the rock
# survey's panoramas on the volume path: the rolling path matches brute force on the unit tests but changed the
# survey's rock heights (tests/rover_sim/test_rock_sites.py, 64 MiB budget), a discrepancy not yet explained.
VOLUME_BUDGET_BYTES = 768 * 2**20
# Largest window-row sum (window rows x image columns x quantised values) kept exact when converted to float32.
_EXACT_FLOAT32 = 2**24
# Row sums below this leave the tag's 8 fractional bits in float32: the fused key (see Engine) is exact.
FUSED_TAG_LIMIT = 2.0**16

# ----------------------------------------------------------------------------------------------------------------
# Step 3: SAD search
# ----------------------------------------------------------------------------------------------------------------


@dataclass
class _Stack:
    """One set of stacking buffers of :meth:`Engine.search_rows` (see :meth:`Engine._stack_runs`): the stacked
    |L - R| bands, their integral image, its sums over the window's rows and, per disparity, the two column views of
    those sums whose difference is the window sum."""

    stack: np.ndarray
    integral: np.ndarray
    band: np.ndarray
    views: list[tuple[np.ndarray, np.ndarray]]


class Engine:
    """The SAD search over one image shape and disparity range, with its buffers (reused between calls).

    Small searches keep every SAD key in ``costs[i, v, u]``. A disparity is written only on the rows that search it,
    so other rows may hold keys from an earlier call: they are read only for winners strictly inside their row's
    window. The columns left of each disparity's first full window are never written and read ``NO_MATCH``.
    Searches whose volume exceeds ``VOLUME_BUDGET_BYTES`` keep two key planes instead and carry the keys at
    ``winner - 1`` and ``winner + 1`` along with the running winner (``rolling``; same results where they count).

    The window sums are exact at any size: they come from integral images (of the stacked bands of several
    disparities, see :meth:`search`), float32 where the whole stack's sum stays below 2^24, else int32 (exact to
    2^31), and the window's row sums (below ``window_px * (W + hw) * max_value``, checked to be < 2^24) are what is
    converted to float32. The key is the exact window sum plus the tag. The fused
    ``addWeighted(band_hi, 1, band_lo, -1, tag)`` adds ``tag`` to ``-band_lo`` first in its SIMD path, which rounds
    the tag once ``band_lo`` (a row sum up to the column) passes 2^16; it is used only on stacks whose row sums all
    stay below ``FUSED_TAG_LIMIT`` (every stack of a 256^2 search: one call and one pass per run fewer, about a tenth
    of the pipeline's time there). Other stacks take an exact subtraction, then the tag (the fused call on every
    stack, used before, gave about 5 % of the keys of the 1024^2 ``bench stereo`` searches a neighbour's index).
    """

    def __init__(
        self,
        shape: tuple[int, int],
        min_disparity: int,
        num_disparities: int,
        window_px: int,
        max_value: int,
    ) -> None:
        h_px, w_px = shape
        hw = window_px // 2
        self.shape, self.min_disparity, self.num_disparities, self.window_px = (
            shape,
            min_disparity,
            num_disparities,
            window_px,
        )
        if window_px * (w_px + hw + 1) * max_value >= _EXACT_FLOAT32:
            raise ValueError(
                f"image width {w_px} px too large for exact SAD sums with a {window_px} px window: "
                f"use width < {_EXACT_FLOAT32 // (window_px * max_value) - hw - 1} px"
            )
        self.rolling = num_disparities * h_px * w_px * 4 > VOLUME_BUDGET_BYTES
        n_planes = 2 if self.rolling else num_disparities  # rolling: the keys of the last two disparities
        # (a NO_MATCH plane before and after: the keys at index -+ 1 are read with one map, see scores)
        self.costs_padded = np.full((n_planes + 2, h_px, w_px), NO_MATCH, np.float32)
        self.costs = self.costs_padded[1:-1]
        if self.rolling:  # running overall best, its neighbours' keys, and "best updated here" of the last two
            self.best_run = np.empty(shape, np.float32)
            self.minus_run = np.empty(shape, np.float32)
            self.plus_run = np.empty(shape, np.float32)
            self.updated = np.zeros((2, h_px, w_px), np.uint8)
        self.best = np.empty((3, h_px, w_px), np.float32)  # best key per disparity class (index mod 3)
        # the least of the classes' second-best keys: updating one plane with every class's candidate
        # max(best_c, key) leaves min_c(second_c), all the uniqueness test needs (see scores)
        self.second = np.empty(shape, np.float32)
        self.best_right = np.empty(shape, np.float32)  # best key per right pixel
        self.tmp = np.empty(shape, np.float32)
        # |L - R| of the bands of several disparities stacked (see search), each with hw rows more above and below
        # (zero outside the image) and hw zero columns on the right: windows there are clipped. float32 integral
        # images are exact below 2^24 (the whole stack's sum), else int32 (exact to 2^31).
        band_rows = h_px + 2 * hw  # a band's stacked rows: at most the whole image's
        n_stack = max(num_disparities, 1) * band_rows
        rows_f32 = (2**24 - 1) // ((w_px + hw + 1) * max_value) - 1
        exact = rows_f32 >= band_rows
        self.stack_rows = min(rows_f32, n_stack) if exact else max(band_rows, min(2048, n_stack))
        self.sdepth = cv2.CV_32F if exact else cv2.CV_32S
        depth = np.float32 if exact else np.int32
        self.depth = depth
        self.window = RowWindow.full(h_px, num_disparities)
        self._full_plan: tuple[RowWindow, list[tuple[int, int]]] | None = None
        self.u_grid, self.v_grid = grids(shape)
        f32, u8 = (lambda: np.empty(shape, np.float32)), (lambda: np.empty(shape, np.uint8))
        self.best_all, self.cost, self.index, self.right_index = f32(), f32(), f32(), f32()
        self.rows, self.key_minus, self.key_plus, self.cost_minus, self.cost_plus = f32(), f32(), f32(), f32(), f32()
        self.far, self.far_tmp, self.best01 = f32(), f32(), f32()
        self.mask, self.mask_tmp = u8(), u8()
        self.no_match = np.full(shape, NO_MATCH, np.float32)
        self.left_q, self.right_q = u8(), u8()  # the images to search: the caller writes them
        self.views = self._views()
        self.parts: list[_Stack] = [self._new_stack()]  # stacking buffers, one per concurrent row part

    def _views(self) -> list[tuple]:
        """Per disparity: its shift, tag and the column slices of every buffer it touches (row-sliced per band)."""
        h_px, w_px = self.shape
        hw = self.window_px // 2
        views: list[tuple] = []
        for i in range(self.num_disparities):
            s = self.min_disparity + i
            n_cols = w_px - s - hw  # left pixels u in [s + hw, w_px) have their window inside the right image
            if n_cols <= 0:
                break
            c = i % 3
            plane = i % 2 if self.rolling else i
            views.append(
                (
                    s,
                    i / TAG,
                    self.left_q[:, s:],
                    self.right_q[:, : w_px - s],
                    self.costs[plane, :, s + hw :],
                    self.best[c, :, s + hw :],
                    self.second[:, s + hw :],
                    self.tmp[:, :n_cols],
                    self.best_right[:, hw : w_px - s],
                    self._rolling_views(i, s + hw) if self.rolling else None,
                )
            )
        return views

    def _rolling_views(self, i: int, u0: int) -> tuple:
        """Columns ``u0:`` of: the previous disparity's keys (NO_MATCH before the first), the running best, the
        keys beside it, "updated here" for this disparity and the previous one; and column ``u0 - 1``."""
        prev = self.costs[(i - 1) % 2] if i > 0 else self.no_match
        cols = slice(u0, None)
        return (
            prev[:, cols],
            self.best_run[:, cols],
            self.minus_run[:, cols],
            self.plus_run[:, cols],
            self.updated[i % 2, :, cols],
            self.updated[(i - 1) % 2, :, cols],
            u0 - 1 if i > 0 else -1,
            self.updated[(i - 1) % 2],
            self.plus_run,
        )

    def plan(self, window: RowWindow | None) -> list[list[tuple[int, int]]]:
        """Set the search's row windows (all disparities if None); per disparity, the bands of rows to search
        (the full search's: made once, shared; callers do not modify bands)."""
        if window is None:
            if self._full_plan is None:
                self._full_plan = (RowWindow.full(self.shape[0], self.num_disparities), [[(0, self.shape[0])]])
            self.window = self._full_plan[0]
            return self._full_plan[1] * self.num_disparities
        self.window = window
        return _row_bands(window, self.num_disparities)

    @staticmethod
    def clip(bands: list[list[tuple[int, int]]], v0: int, v1: int) -> list[list[tuple[int, int]]]:
        """The plan for rows ``v0:v1`` (:func:`clip_bands`)."""
        return clip_bands(bands, v0, v1)

    def search(self, window: RowWindow | None, rows: tuple[int, int] | None = None) -> None:
        """Search ``self.left_q`` against ``self.right_q`` (quantised images, written by the caller).

        ``rows``: the running minima are reset on these rows only (all rows that search anything must be inside;
        decode only these rows).
        """
        bands = self.plan(window)
        self.search_rows(bands, *(rows if rows is not None else (0, self.shape[0])))

    def search_rows(self, bands: list[list[tuple[int, int]]], v0: int, v1: int, part: int = 0) -> None:
        """The search of ``bands`` (from :meth:`plan`, all inside rows ``v0:v1``: see :func:`clip_bands`), the running
        minima reset on rows ``v0:v1``, stacking in buffer set ``part``.

        Row ranges searched with different parts may run concurrently (threads): they write disjoint rows of the
        shared buffers. Every key is an exact integer sum plus its tag, so the results do not depend on how the
        rows are split. The rolling search carries state across rows' columns: one part, all rows.
        """
        if self.rolling and (part or any(a < v0 or b > v1 for runs in bands for a, b in runs)):
            raise ValueError("the rolling search runs in one part covering every searched row")
        self.best[:, v0:v1].fill(NO_MATCH)
        self.second[v0:v1].fill(NO_MATCH)
        self.best_right[v0:v1].fill(NO_MATCH)
        if self.rolling:
            for buf in (self.best_run, self.minus_run, self.plus_run):
                buf[v0:v1].fill(NO_MATCH)
            self.updated[:, v0:v1].fill(0)
        while len(self.parts) <= part:
            self.parts.append(self._new_stack())
        buffers = self.parts[part]
        subtract, add, vmin, vmax, f32 = cv2.subtract, cv2.add, cv2.min, cv2.max, cv2.CV_32F
        add_weighted, fused = cv2.addWeighted, False
        # (views stop at the first disparity with no column left in the image)
        bands_v = list(zip(self.views, buffers.views, bands, strict=False))
        runs_all = [(view, a, b) for view, _, runs in bands_v for a, b in runs]
        offsets: list[int] = []  # each run's first row in the stack (filled a stack at a time)
        last = None
        k = 0
        for view, (band_hi, band_lo), runs in bands_v:
            _, tag, _, _, costs, best, second, tmp, best_right, rolling = view
            for a, b in runs:
                if k == len(offsets):
                    fused = self._stack_runs(runs_all, k, offsets, buffers)
                off, n = offsets[k], b - a
                k += 1
                key = costs[a:b]  # (positional arguments: OpenCV parses keywords more slowly)
                if fused:  # exact: every row sum of this stack is below 2^16 (see _stack_runs)
                    add_weighted(band_hi[off : off + n], 1.0, band_lo[off : off + n], -1.0, tag, key, f32)
                else:
                    subtract(band_hi[off : off + n], band_lo[off : off + n], key, None, f32)  # exact window sums ...
                    add(key, tag, key)  # ... then the tag
                best_c, second_c = best[a:b], second[a:b]
                vmin(second_c, vmax(best_c, key, tmp[a:b]), second_c)
                vmin(best_c, key, best_c)
                right_c = best_right[a:b]
                vmin(right_c, key, right_c)
                if rolling is not None:
                    _carry_neighbours(key, rolling, a, b)
            if rolling is not None and last is not None:  # the previous disparity's "updated" is consumed: clear it
                for a, b in last[1]:
                    rolling[7][a:b].fill(0)
            last = (rolling, runs)
        if last is not None and last[0] is not None:  # the last disparity's winners have no right neighbour
            _, _, _, plus, updated, _, _, _, _ = last[0]
            for a, b in last[1]:
                cv2.copyTo(self.no_match[a:b, : plus.shape[1]], updated[a:b], plus[a:b])

    def forget_stacks(self) -> None:
        """Zero the stacks: later searches' stale columns (see :meth:`_stack_runs`) then hold nothing above
        ``max_value`` even if this search's images did."""
        for buffers in self.parts:
            buffers.stack.fill(0)

    def _new_stack(self) -> _Stack:
        h_px, w_px = self.shape
        hw, win = self.window_px // 2, self.window_px
        band = np.empty((self.stack_rows, w_px + hw + 1), self.depth)
        views = [(band[:, view[0] + win :], band[:, view[0] : w_px - hw]) for view in self.views]
        return _Stack(
            np.zeros((self.stack_rows, w_px + hw), np.uint8),
            np.empty((self.stack_rows + 1, w_px + hw + 1), self.depth),
            band,
            views,
        )

    def _stack_runs(self, runs: list[tuple], k0: int, offsets: list[int], buffers: _Stack) -> bool:
        """|L - R| of runs ``k0, k0 + 1, ...`` (as many as the stack holds), each with hw rows more above and below,
        stacked; then one integral image and one subtraction give the sums over ``window_px`` rows of all of them
        (row ``offsets[k] + j`` of ``band``: run k's row a + j). A column sum never mixes two runs. The columns left
        of a run's shift keep an earlier run's differences (each at most ``max_value``, like the others): they add
        the same amount to both ends of every window's row sum, and the sums are exact (see :class:`Engine`), so
        they cancel exactly."""
        h_px, w_px = self.shape
        hw, win = self.window_px // 2, self.window_px
        stack, absdiff = buffers.stack, cv2.absdiff
        row = 0
        for view, a, b in runs[k0:]:
            n_rows = b - a + 2 * hw
            if row + n_rows > self.stack_rows:
                break
            s, left, right = view[0], view[2], view[3]
            r0, r1 = max(a - hw, 0), min(b + hw, h_px)
            top, bottom = row + r0 - (a - hw), row + r1 - (a - hw)
            absdiff(left[r0:r1], right[r0:r1], stack[top:bottom, s:w_px])
            if top > row:  # rows above the image
                stack[row:top].fill(0)
            if bottom < row + n_rows:  # ... and below
                stack[bottom : row + n_rows].fill(0)
            offsets.append(row)
            row += n_rows
        integ = cv2.integral(stack[:row], buffers.integral[: row + 1], self.sdepth)
        band = cv2.subtract(integ[win:], integ[: row + 1 - win], buffers.band[: row + 1 - win])
        # The largest row sum (the last column: sums grow along a row) below 2^16: ``-band_lo + tag``, which the
        # fused addWeighted forms first in its SIMD path, then keeps the tag's 8 fractional bits exactly.
        return self.sdepth == cv2.CV_32F and float(band[:, -1].max()) < FUSED_TAG_LIMIT

    def winners(self, v0: int = 0, v1: int | None = None, none_index: float = -1.0) -> tuple[np.ndarray, np.ndarray]:
        """Winning index of every left pixel (float32; 0 where none, see found) and every right pixel
        (``none_index`` if none), on rows ``v0:v1`` (views of workspace buffers).

        A key's index is its fractional part times 256 (exact: SAD < 2^16 and 8 fractional bits fit in float32).
        """
        rows = slice(v0, v1)
        self.rows_decoded = rows
        best01 = cv2.min(self.best[0, rows], self.best[1, rows], self.best01[rows])
        best = cv2.min(best01, self.best[2, rows], self.best_all[rows])
        cost = np.floor(best, out=self.cost[rows])
        # (key - SAD) * TAG: both products are exact, so is their difference (an integer < 2^24)
        index = cv2.addWeighted(best, float(TAG), cost, -float(TAG), 0.0, self.index[rows])
        best_right = self.best_right[rows]
        right = np.floor(best_right, out=self.right_index[rows])
        right = cv2.addWeighted(best_right, float(TAG), right, -float(TAG), 0.0, right)
        none = cv2.compare(best_right, NO_MATCH, cv2.CMP_GE, self.mask_tmp[rows])
        cv2.copyTo(_constant_f32(self.shape, none_index)[rows], none, right)
        return index, right

    def found(self) -> np.ndarray:
        """Where the left pixel had any candidate (bool; call after winners)."""
        return self.cost[self.rows_decoded] < NO_MATCH

    def scores(
        self, index: np.ndarray, rows: slice | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """SAD of the winner and of index -+ 1, and the best SAD more than 1 px away (``rows``: those decoded by
        winners; pass them when several threads decode disjoint rows).

        The neighbours' keys are read back from ``costs`` (nearest-neighbour remap of its (D * H, W) view) and are
        valid only where the winner lies strictly inside its row's window (see edge_mask).
        """
        h_px, w_px = self.shape
        n = self.num_disparities
        sl = rows if rows is not None else self.rows_decoded
        key_minus, key_plus, far_tmp, stack_row = self.key_minus[sl], self.key_plus[sl], self.far_tmp[sl], self.rows[sl]
        if self.rolling:
            np.copyto(key_minus, self.minus_run[sl])
            np.copyto(key_plus, self.plus_run[sl])
        elif h_px * n < 32000:  # remap converts coordinates to int16
            # row index * H + v of the padded volume holds the key at (index - 1, v); 2 H rows further, (index + 1, v)
            rows = cv2.scaleAdd(index, float(h_px), self.v_grid[sl], stack_row)
            stacked = self.costs_padded.reshape(-1, w_px)
            border = cv2.BORDER_CONSTANT
            for key, src in ((key_minus, stacked), (key_plus, stacked[2 * h_px :])):
                cv2.remap(src, self.u_grid[sl], rows, cv2.INTER_NEAREST, key, border, NO_MATCH)
        else:
            rows = cv2.scaleAdd(index, float(h_px), self.v_grid[sl], dst=stack_row)  # row of (index, v) in costs
            flat = rows.astype(np.int64) * w_px + np.arange(w_px)
            keys = self.costs.reshape(-1)
            np.copyto(key_minus, keys.take(flat - h_px * w_px, mode="clip"))
            np.copyto(key_plus, keys.take(flat + h_px * w_px, mode="clip"))
        cost_minus = np.floor(key_minus, out=self.cost_minus[sl])
        cost_plus = np.floor(key_plus, out=self.cost_plus[sl])
        # Best score more than 1 px from the winner. Each class holds exactly one of the disparities w - 1, w, w + 1;
        # if a class's best is that one its second is far, else its best is. Sorted, the class bests are the
        # winner's key, then mid and top: the far minimum among them is mid unless mid is a neighbour's key, else
        # top unless top is; the class seconds (their least: self.second) are always candidates.
        b0, b1, b2 = self.best[0, sl], self.best[1, sl], self.best[2, sl]
        top = cv2.max(b0, b1, far_tmp)
        mid = cv2.max(self.best01[sl], cv2.min(top, b2, stack_row), stack_row)
        cv2.max(top, b2, top)
        near, tmp_mask = self.mask[sl], self.mask_tmp[sl]
        for cand in (top, mid):
            cv2.compare(cand, key_minus, cv2.CMP_EQ, near)
            cv2.bitwise_or(near, cv2.compare(cand, key_plus, cv2.CMP_EQ, tmp_mask), near)
            # top: NO_MATCH where near; mid: top where near (the candidate: mid, else top, else none)
            cv2.copyTo(self.no_match[sl] if cand is top else top, near, cand)
        far = cv2.min(self.second[sl], mid, self.far[sl])
        return self.cost[sl], cost_minus, cost_plus, np.floor(far, out=far)


def _carry_neighbours(key: np.ndarray, views: tuple, a: int, b: int) -> None:
    """Rolling search, rows ``a:b`` of one disparity: where the previous disparity became the running best, ``key``
    is its right neighbour's; where this one does, the previous key is its left neighbour's."""
    prev, best, minus, plus, updated, updated_prev, u_edge, updated_prev_full, plus_full = views
    cv2.copyTo(key, updated_prev[a:b], plus[a:b])
    new = cv2.compare(key, best[a:b], cv2.CMP_LT, dst=updated[a:b])
    cv2.copyTo(prev[a:b], new, minus[a:b])
    cv2.min(best[a:b], key, dst=best[a:b])
    if u_edge >= 0:  # the previous disparity's last column is out of this one's reach: no right neighbour there
        edge = updated_prev_full[a:b, u_edge] != 0
        if edge.any():
            plus_full[a:b, u_edge][edge] = NO_MATCH


def _row_bands(window: RowWindow, num_disparities: int, merge_gap: int = 40) -> list[list[tuple[int, int]]]:
    """For each disparity index, the bands ``[a, b)`` of rows that search it (bands at most ``merge_gap`` rows apart
    are merged: each band costs a few OpenCV calls and half a window of rows above and below)."""
    lo, hi = window.lo, window.hi
    h_px = lo.size
    if not lo.any() and (hi == num_disparities - 1).all():  # the full window: every row
        return [[(0, h_px)] for _ in range(num_disparities)]
    # segments of rows sharing one window (row_search_window gives the same window to about 4 rows at a time)
    change = np.ones(h_px, bool)
    np.not_equal(lo[1:], lo[:-1], out=change[1:])
    change[1:] |= hi[1:] != hi[:-1]
    seg_start = np.flatnonzero(change)
    seg_end = np.append(seg_start[1:], h_px)
    i, n_s = np.arange(num_disparities)[:, None], seg_start.size + 1
    inside = np.zeros((num_disparities, n_s + 1), bool)
    np.less_equal(lo[seg_start], i, out=inside[:, 1:-1])
    inside[:, 1:-1] &= i <= hi[seg_start]
    # runs in (disparity, segment) order: the segment where a run starts, and one past the one where it ends
    starts_i, starts_s = np.divmod(np.flatnonzero(inside[:, 1:] > inside[:, :-1]), n_s)
    bands: list[list[tuple[int, int]]] = [[] for _ in range(num_disparities)]
    if starts_i.size == 0:
        return bands
    starts_v = seg_start[starts_s]
    ends_v = seg_end[np.flatnonzero(inside[:, 1:] < inside[:, :-1]) % n_s - 1]
    # a run opens a new band unless it follows a run of the same disparity at most merge_gap rows before
    opens = np.ones(starts_i.size, bool)
    opens[1:] = (starts_i[1:] != starts_i[:-1]) | (starts_v[1:] - ends_v[:-1] > merge_gap)
    first = np.flatnonzero(opens)
    last = np.append(first[1:] - 1, starts_i.size - 1)
    for k, a, b in zip(starts_i[first].tolist(), starts_v[first].tolist(), ends_v[last].tolist(), strict=True):
        bands[k].append((a, b))
    return bands


def clip_bands(bands: list[list[tuple[int, int]]], v0: int, v1: int) -> list[list[tuple[int, int]]]:
    """The bands of :meth:`Engine.plan` cut to rows ``v0:v1`` (every searched row inside stays searched)."""
    return [[(max(a, v0), min(b, v1)) for a, b in runs if a < v1 and b > v0] for runs in bands]


def grids(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """float32 column and row coordinate images (read-only views of shared arrays)."""
    h_px, w_px = shape
    grids = _GRIDS.get(w_px)
    if grids is None or grids[0].shape[0] < h_px:
        u_grid = np.tile(np.arange(w_px, dtype=np.float32), (h_px, 1))
        v_grid = np.tile(np.arange(h_px, dtype=np.float32)[:, None], (1, w_px))
        u_grid.flags.writeable = v_grid.flags.writeable = False
        grids = _GRIDS[w_px] = (u_grid, v_grid)
    return grids[0][:h_px], grids[1][:h_px]


_GRIDS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _constant_f32(shape: tuple[int, int], value: float) -> np.ndarray:
    """A read-only float32 image filled with ``value`` (kept per shape and value)."""
    arr = _CONSTANTS.get((shape, value))
    if arr is None:
        if len(_CONSTANTS) >= 16:
            _CONSTANTS.clear()
        arr = _CONSTANTS[(shape, value)] = np.full(shape, value, np.float32)
        arr.flags.writeable = False
    return arr


_CONSTANTS: dict[tuple, np.ndarray] = {}


# ----------------------------------------------------------------------------------------------------------------
# Step 4: quadratic sub-pixel interpolation
# ----------------------------------------------------------------------------------------------------------------


def subpixel_quadratic(cost_minus: np.ndarray, cost: np.ndarray, cost_plus: np.ndarray) -> np.ndarray:
    """Step 4 (paper: "subpixel disparities are computed by quadratic interpolation of SAD scores").

    Vertex of the parabola through ``(-1, cost_minus), (0, cost), (1, cost_plus)``: an offset in [-0.5, 0.5] px when
    ``cost`` is the smallest of the three, NaN where the three scores are flat (no curvature).
    """
    cm = np.asarray(cost_minus, dtype=np.float64)
    cp = np.asarray(cost_plus, dtype=np.float64)
    curvature = cm + cp - 2.0 * np.asarray(cost, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = (cm - cp) / (2.0 * curvature)
    return np.where(curvature > 0, offset, np.float32(np.nan)).astype(np.float32)


def subpixel(
    cost_minus: np.ndarray, cost: np.ndarray, cost_plus: np.ndarray, curvature: np.ndarray, offset: np.ndarray
) -> None:
    """:func:`subpixel_quadratic` for integer SAD scores in float32 (differences exact): fills ``curvature``
    (cm + cp - 2 c) and ``offset`` (meaningful where 0 < curvature < _CURVATURE_LIMIT)."""
    cv2.add(cost_minus, cost_plus, dst=curvature)
    cv2.scaleAdd(cost, -2.0, curvature, dst=curvature)
    cv2.divide(cv2.subtract(cost_minus, cost_plus, dst=offset), curvature, dst=offset, scale=0.5)
