"""Step 3 of the MER stereo pipeline (Maimone et al. 2005, section 4.1), the SAD search, as one compiled pass per row:
:class:`FusedEngine`, the engine :func:`nav.stereo.compute_disparity` uses where numba is installed.

It gives the same results as the OpenCV engine (:class:`nav.stereo.sad.Engine`, the reference and the fallback
without numba): the same searched (row, disparity) set, the same exact integer window sums, the same keys
``SAD * 256 + index`` (here int32 rather than float32 ``SAD + index / 256``: the same order), so the same winners,
neighbour scores, uniqueness candidates and right-referenced winners wherever the checks read them
(``tests/nav/test_stereo_engines.py`` compares the two engines' disparity maps bit for bit).

Why a compiled pass: the OpenCV engine streams every key through memory five times (the key, its class's best and
second, the right image's best) plus the stacking, in about 800 short calls per 256^2 pair; its time there swings with
the other core's memory traffic (``bench stereo``: 1.1x StereoBM on a quiet machine, 1.4-1.6x beside a process
copying 64 MiB arrays). Here a row's state (the running bests, the neighbours' keys, the column sums of every
disparity) stays in L1/L2 and each key is formed and consumed in registers.

Per row ``v`` and searched disparity index ``i`` (shift ``s = min_disparity + i``):

1. the column sums ``C_i(u) = sum_r |L(r, u) - R(r, u - s)|`` over the window's rows ``v - hw .. v + hw`` (rows
   outside the image count zero) are updated from row ``v - 1``'s by one row in and one row out, or formed afresh
   when row ``v - 1`` did not search ``i``;
2. the window sum at ``u`` (``s + hw <= u < W``: the window lies inside the right image) adds ``C_i`` over
   ``u - hw .. u + hw``, columns past the right border counting zero;
3. the key updates the running best (and the keys at index -+ 1 beside it), the best of the key's disparity class
   ``i mod 3`` and the least second-best of the classes (the uniqueness test's candidates, see
   :meth:`nav.stereo.sad.Engine.scores`), and the running best of the right pixel ``u - s``.

The row's results are decoded into the float32 images the checks read: winner index, its SAD, the SAD at index -+ 1
(``NO_MATCH`` where not searched), the best SAD more than 1 px away, and the right pixels' best keys.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from nav.stereo.params import NO_MATCH, TAG, RowWindow

TAG_BITS = 8  # key = SAD << TAG_BITS | index
assert 1 << TAG_BITS == TAG
NO_MATCH_KEY = int(NO_MATCH) << TAG_BITS  # 2^28: decodes to SAD NO_MATCH, index 0
NO_ROW = -(2**30)  # col_row's "no column sums held"
MERGE_GAP_ROWS = 40  # rows of one disparity at most this far apart are searched in one band (as the OpenCV engine)


@njit(cache=True, nogil=True)
def searched_mask(lo: np.ndarray, hi: np.ndarray, num_disparities: int, merge_gap: int, out: np.ndarray) -> None:
    """``out[v, i] = 1`` where row ``v`` searches index ``i``: inside its window ``lo[v] <= i <= hi[v]``, or in a gap of
    at most ``merge_gap`` rows between two rows that search ``i`` (the OpenCV engine's merged bands)."""
    h_px = lo.size
    out[:, :] = 0
    for i in range(num_disparities):
        end = -1  # one past the last row inside i's windows so far
        for v in range(h_px):
            if lo[v] <= i and i <= hi[v]:
                if end >= 0 and v > end and v - end <= merge_gap:
                    out[end:v, i] = 1
                out[v, i] = 1
                end = v + 1


@njit(cache=True, nogil=True, boundscheck=False)
def sad_rows(
    left: np.ndarray,
    right: np.ndarray,
    mask: np.ndarray,
    min_disparity: int,
    hw: int,
    v0: int,
    v1: int,
    colsum: np.ndarray,
    col_row: np.ndarray,
    out_index: np.ndarray,
    out_cost: np.ndarray,
    out_minus: np.ndarray,
    out_plus: np.ndarray,
    out_far: np.ndarray,
    out_right_key: np.ndarray,
) -> None:
    """The search of rows ``v0:v1`` (see the module docstring). ``colsum`` (D, W + hw) int32 and ``col_row`` (D,)
    int32 carry each disparity's column sums and the row they hold (``NO_ROW``: none); one set per thread."""
    h_px, w_px = left.shape
    n_disp = mask.shape[1]
    win = 2 * hw + 1
    nm = NO_MATCH_KEY
    best = np.empty(w_px, np.int32)
    minus = np.empty(w_px, np.int32)
    plus = np.empty(w_px, np.int32)
    second = np.empty(w_px, np.int32)
    best_c = np.empty((3, w_px), np.int32)
    right_best = np.empty(w_px, np.int32)
    acc = np.empty(w_px, np.int32)
    no_match = np.full(w_px, nm, np.int32)
    keys = np.empty((2, w_px), np.int32)  # this index's keys (from its first column) and the previous searched one's
    for v in range(v0, v1):
        best[:] = nm
        minus[:] = nm
        plus[:] = nm
        second[:] = nm
        best_c[:, :] = nm
        right_best[:] = nm
        prev_i, u0_prev = -2, 0  # the last index searched on this row, and its first column
        for i in range(n_disp):
            if mask[v, i] == 0:
                continue
            s = min_disparity + i
            u0 = s + hw
            if u0 >= w_px:
                break  # no column has its window inside the right image (nor at any larger shift)
            cs = colsum[i]
            n_sum = w_px - s  # columns s..W-1 have column sums (slices below: numba then skips the index checks)
            cs_s = cs[s:w_px]
            # 1. column sums over the window's rows
            if col_row[i] == v - 1:
                r = v + hw
                if r < h_px:
                    lr, rr = left[r, s:], right[r, :n_sum]
                    for u in range(n_sum):
                        cs_s[u] += abs(np.int32(lr[u]) - np.int32(rr[u]))
                r = v - hw - 1
                if r >= 0:
                    lr, rr = left[r, s:], right[r, :n_sum]
                    for u in range(n_sum):
                        cs_s[u] -= abs(np.int32(lr[u]) - np.int32(rr[u]))
            else:
                cs_s[:] = 0
                for r in range(max(v - hw, 0), min(v + hw + 1, h_px)):
                    lr, rr = left[r, s:], right[r, :n_sum]
                    for u in range(n_sum):
                        cs_s[u] += abs(np.int32(lr[u]) - np.int32(rr[u]))
            col_row[i] = v
            # 2. window sums (cs is zero past the right border) of the left pixels u0.., as keys
            n = w_px - u0
            src = cs[s : s + n]
            for j in range(n):
                acc[j] = src[j]
            for k in range(1, win):
                src = cs[s + k : s + k + n]
                for j in range(n):
                    acc[j] += src[j]
            cur = keys[i & 1, :n]
            if prev_i == i - 1:  # the previous index's keys at the same columns
                prev = keys[(i - 1) & 1, u0 - u0_prev : u0 - u0_prev + n]
            else:
                prev = no_match[:n]
            tag = np.int32(i)
            for j in range(n):
                cur[j] = acc[j] * np.int32(TAG) + tag
            # 3. running best with its neighbours' keys
            best_u, minus_u, plus_u = best[u0:], minus[u0:], plus[u0:]
            was_prev = np.int32(i - 1)
            for j in range(n):
                key = cur[j]
                b = best_u[j]
                if (b & (TAG - 1)) == was_prev and b < nm:
                    plus_u[j] = key  # the previous index is the running best: this is its right neighbour
                if key < b:
                    best_u[j] = key
                    plus_u[j] = nm
                    minus_u[j] = prev[j]
            # ... the class's best and the classes' least second-best
            bc, second_u = best_c[i % 3, u0:], second[u0:]
            for j in range(n):
                key = cur[j]
                second_u[j] = min(second_u[j], max(bc[j], key))
                bc[j] = min(bc[j], key)
            # ... the right pixel's best (right pixel hw + j)
            right_u = right_best[hw : hw + n]
            for j in range(n):
                right_u[j] = min(right_u[j], cur[j])
            u0_prev = u0
            prev_i = i
        # decode the row
        for u in range(w_px):
            b = best[u]
            w = b & (TAG - 1)
            out_index[v, u] = w
            out_cost[v, u] = b >> TAG_BITS
            out_minus[v, u] = minus[u] >> TAG_BITS
            out_plus[v, u] = plus[u] >> TAG_BITS
            far = second[u]
            for c in range(3):
                k = best_c[c, u]
                if k < nm and abs((k & (TAG - 1)) - w) > 1:
                    far = min(far, k)
            out_far[v, u] = far >> TAG_BITS
            out_right_key[v, u] = right_best[u]


@njit(cache=True, nogil=True)
def decode_right(keys: np.ndarray, none_index: float, out: np.ndarray) -> None:
    """The right pixels' winning index (float32), ``none_index`` where they had no candidate."""
    h_px, w_px = keys.shape
    for v in range(h_px):
        for u in range(w_px):
            k = keys[v, u]
            out[v, u] = none_index if k >= NO_MATCH_KEY else k & (TAG - 1)


class FusedEngine:
    """The SAD search of :class:`nav.stereo.sad.Engine`'s interface (``plan``, ``search_rows``, ``winners``,
    ``scores``), compiled: see the module docstring. Exact at every size (int32 sums; keys below 2^31)."""

    rolling = False  # (no SAD volume to budget: every result is formed row by row)

    def __init__(
        self, shape: tuple[int, int], min_disparity: int, num_disparities: int, window_px: int, max_value: int
    ) -> None:
        h_px, w_px = shape
        if window_px * window_px * max_value * TAG + num_disparities >= 2**31:
            raise ValueError(f"window {window_px} px with values up to {max_value}: keys would overflow int32")
        self.shape, self.min_disparity, self.num_disparities, self.window_px = (
            shape,
            min_disparity,
            num_disparities,
            window_px,
        )
        self.left_q, self.right_q = np.empty(shape, np.uint8), np.empty(shape, np.uint8)
        f32 = lambda: np.empty(shape, np.float32)  # noqa: E731
        self.index, self.cost, self.cost_minus, self.cost_plus, self.far, self.right_index = (f32() for _ in range(6))
        self.right_key = np.empty(shape, np.int32)
        self.mask = np.zeros((h_px, num_disparities), np.uint8)
        self.window = RowWindow.full(h_px, num_disparities)
        self._full_mask = np.ones((h_px, num_disparities), np.uint8)
        self._parts: list[tuple[np.ndarray, np.ndarray]] = []  # per concurrent row part: column sums, their row
        self.rows_decoded = slice(0, h_px)

    def plan(self, window: RowWindow | None) -> np.ndarray:
        """Set the search's row windows (all disparities if None); the (H, D) mask of searched rows and indices."""
        if window is None:
            self.window = RowWindow.full(self.shape[0], self.num_disparities)
            return self._full_mask
        self.window = window
        lo, hi = np.ascontiguousarray(window.lo, np.int32), np.ascontiguousarray(window.hi, np.int32)
        if lo.shape != (self.shape[0],) or hi.shape != lo.shape:
            raise ValueError(f"row window of {lo.shape} and {hi.shape} rows for images of {self.shape[0]} rows")
        searched_mask(lo, hi, self.num_disparities, MERGE_GAP_ROWS, self.mask)
        return self.mask

    @staticmethod
    def clip(plan: np.ndarray, v0: int, v1: int) -> np.ndarray:
        """The plan for rows ``v0:v1`` (the search takes its rows as arguments)."""
        return plan

    def search(self, window: RowWindow | None, rows: tuple[int, int] | None = None) -> None:
        self.search_rows(self.plan(window), *(rows if rows is not None else (0, self.shape[0])))

    def search_rows(self, plan: np.ndarray, v0: int, v1: int, part: int = 0) -> None:
        """Rows ``v0:v1`` of the plan, with column-sum buffer set ``part`` (parts on disjoint rows may run in
        concurrent threads: the kernel releases the GIL)."""
        while len(self._parts) <= part:
            self._parts.append(
                (
                    np.zeros((self.num_disparities, self.shape[1] + self.window_px), np.int32),
                    np.full(self.num_disparities, NO_ROW, np.int32),
                )
            )
        colsum, col_row = self._parts[part]
        col_row.fill(NO_ROW)
        sad_rows(
            self.left_q,
            self.right_q,
            plan,
            self.min_disparity,
            self.window_px // 2,
            v0,
            v1,
            colsum,
            col_row,
            self.index,
            self.cost,
            self.cost_minus,
            self.cost_plus,
            self.far,
            self.right_key,
        )

    def forget_stacks(self) -> None:
        """(Nothing is kept between searches: the OpenCV engine's interface.)"""

    def winners(self, v0: int = 0, v1: int | None = None, none_index: float = -1.0) -> tuple[np.ndarray, np.ndarray]:
        """Winning index of every left pixel (float32; 0 where none, see found) and every right pixel
        (``none_index`` if none), on rows ``v0:v1``."""
        rows = slice(v0, v1)
        self.rows_decoded = rows
        decode_right(self.right_key[rows], float(none_index), self.right_index[rows])
        return self.index[rows], self.right_index[rows]

    def found(self) -> np.ndarray:
        """Where the left pixel had any candidate (bool; call after winners)."""
        return self.cost[self.rows_decoded] < NO_MATCH

    def scores(
        self, index: np.ndarray, rows: slice | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """SAD of the winner and of index -+ 1 (``NO_MATCH`` where not searched), and the best SAD more than 1 px
        from the winner, on ``rows`` (default: those decoded by winners)."""
        sl = rows if rows is not None else self.rows_decoded
        return self.cost[sl], self.cost_minus[sl], self.cost_plus[sl], self.far[sl]
