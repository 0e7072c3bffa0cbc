"""Statistics of a benchmark figure over seeds: summaries, a paired regression test and its power.

A closed-loop drive is a chaotic system: the same scenario on another seed, CPU or build drives another route, so a
figure is a distribution over seeds (evo's APE/RPE statistics and leaderboards that report many sequences are the
model). Everything here is pure numpy; every resampling takes a seed.

- :func:`summarize`: median, mean, a 90 % percentile-bootstrap interval of the median, the worst value and the
  per-seed values of one metric.
- :func:`signed_rank_p`: the exact one-sided Wilcoxon signed-rank test on paired differences (Wilcoxon 1945), by
  enumerating every sign pattern; its smallest attainable p with ``n`` non-zero pairs is ``2**-n``
  (:func:`min_attainable_p`), so a family-wise 1 % over ``m`` tests needs ``2**-n < 0.01 / m``.
- :func:`holm`: Holm's step-down procedure (Holm 1979) over a family of tests.
- :func:`min_detectable_shift`: the smallest shift of the paired differences that the test detects with the wanted
  power at a given level, found by resampling the observed differences with the shift added (a bootstrap power
  analysis of the same test, not a normal approximation).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cache

import numpy as np

CI_LEVEL = 0.90
BOOTSTRAP_RESAMPLES = 4000
MAX_EXACT_PAIRS = 20  # 2**20 sign patterns: beyond this the exact enumeration is not worth its memory


@dataclass(frozen=True)
class Summary:
    """One metric over seeds. ``None`` figures (not measured on that seed) are kept in ``per_seed`` and left out of
    the statistics; ``worst`` is the maximum for a lower-is-better metric and the minimum otherwise."""

    median: float | None
    mean: float | None
    ci90: tuple[float, float] | None
    worst: float | None
    per_seed: dict[int, float | None]

    @property
    def n(self) -> int:
        return sum(v is not None for v in self.per_seed.values())

    def as_json(self) -> dict:
        return {
            "median": self.median,
            "mean": self.mean,
            "ci90": list(self.ci90) if self.ci90 is not None else None,
            "worst": self.worst,
            "per_seed": {str(s): v for s, v in self.per_seed.items()},
        }


def bootstrap_ci(
    values: Sequence[float],
    statistic: Callable[[np.ndarray], np.ndarray] = lambda a: np.median(a, axis=-1),
    level: float = CI_LEVEL,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile-bootstrap interval of ``statistic`` (Efron & Tibshirani 1993, ch. 13), resampling with a seeded
    generator; ``statistic`` maps an (resamples, n) array to (resamples,)."""
    a = np.asarray(values, float)
    if a.size == 1:
        return float(a[0]), float(a[0])
    rng = np.random.default_rng(seed)
    draws = statistic(a[rng.integers(0, a.size, size=(resamples, a.size))])
    lo, hi = np.quantile(draws, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


def _round(v: float, digits: int = 4) -> float:
    return float(round(v, digits))


def summarize(per_seed: Mapping[int, float | None], higher_is_better: bool = False) -> Summary:
    """:class:`Summary` of one metric's per-seed values (seed -> value or None)."""
    kept = {int(s): (None if v is None or not math.isfinite(v) else float(v)) for s, v in per_seed.items()}
    vals = [v for v in kept.values() if v is not None]
    if not vals:
        return Summary(None, None, None, None, kept)
    lo, hi = bootstrap_ci(vals)
    worst = min(vals) if higher_is_better else max(vals)
    return Summary(_round(float(np.median(vals))), _round(float(np.mean(vals))), (_round(lo), _round(hi)),
                   _round(worst), kept)  # fmt: skip


def percentile(values: Sequence[float], q: float) -> float:
    """The ``q``-th percentile (0-100) by linear interpolation between order statistics (numpy's default)."""
    return float(np.percentile(np.asarray(values, float), q))


# ------------------------------------------------------------------------------------ the paired rank test


@cache
def _sign_patterns(n: int) -> np.ndarray:
    """Every assignment of signs to ``n`` pairs as a (2**n, n) array of 0/1."""
    idx = np.arange(2**n, dtype=np.int64)[:, None]
    return ((idx >> np.arange(n, dtype=np.int64)) & 1).astype(np.float64)


def _ranks(a: np.ndarray) -> np.ndarray:
    """Ranks 1..n with ties given their average rank."""
    order = np.argsort(a, kind="stable")
    ranks = np.empty(a.size)
    ranks[order] = np.arange(1, a.size + 1)
    for v in np.unique(a):
        tie = a == v
        if tie.sum() > 1:
            ranks[tie] = ranks[tie].mean()
    return ranks


def signed_rank_p(differences: Sequence[float], alternative: str = "greater", tol: float = 1e-12) -> float:
    """Exact p of the Wilcoxon signed-rank test that the paired differences are centred above zero
    (``alternative="greater"``), below it (``"less"``) or away from it (``"two-sided"``).

    Zero differences (|d| <= ``tol``) are dropped (Wilcoxon's treatment); with no pair left p is 1. Tied magnitudes
    get average ranks and the null distribution is enumerated with those ranks, so the p is exact with ties too.
    """
    d = np.asarray(differences, float)
    d = d[np.abs(d) > tol]
    n = d.size
    if n == 0:
        return 1.0
    if n > MAX_EXACT_PAIRS:
        raise ValueError(f"exact signed-rank test on {n} pairs (at most {MAX_EXACT_PAIRS})")
    r = _ranks(np.abs(d))
    t_obs = float(r[d > 0].sum())
    null = _sign_patterns(n) @ r  # T+ under every sign pattern
    eps = 1e-9
    if alternative == "greater":
        return float(np.mean(null >= t_obs - eps))
    if alternative == "less":
        return float(np.mean(null <= t_obs + eps))
    centre = r.sum() / 2
    return float(np.mean(np.abs(null - centre) >= abs(t_obs - centre) - eps))


def _signed_rank_p_rows(rows: np.ndarray, tol: float = 1e-12) -> np.ndarray:
    """:func:`signed_rank_p` (``"greater"``) of every row of ``rows`` at once: average ranks of the non-zero
    magnitudes (zeros get rank 0, so they add nothing under any sign pattern: the same null as dropping them) and
    every sign pattern's statistic as one matrix product."""
    mags = np.abs(rows)
    nz = mags > tol
    less = np.sum((mags[:, None, :] < mags[:, :, None]) & nz[:, None, :], axis=2)
    equal = np.sum((mags[:, None, :] == mags[:, :, None]) & nz[:, None, :], axis=2)
    ranks = np.where(nz, less + (equal + 1) / 2.0, 0.0)
    t_obs = np.sum(np.where(rows > tol, ranks, 0.0), axis=1)
    null = _sign_patterns(rows.shape[1]) @ ranks.T  # (2**n, rows)
    return np.mean(null >= t_obs[None, :] - 1e-9, axis=0)


def min_attainable_p(n_pairs: int, alternative: str = "greater") -> float:
    """The smallest p the exact signed-rank test can return with ``n_pairs`` non-zero pairs."""
    p = 0.5**n_pairs
    return min(1.0, 2 * p) if alternative == "two-sided" else p


def holm(p_values: Sequence[float], alpha: float) -> tuple[list[bool], list[float]]:
    """Holm's step-down procedure: (rejected, threshold) per test, in input order. The k-th smallest p is compared
    with ``alpha / (m - k)``; once one is not rejected, no larger p is. Controls the family-wise error at ``alpha``."""
    m = len(p_values)
    order = sorted(range(m), key=lambda i: p_values[i])
    rejected, thresholds = [False] * m, [alpha / m] * m
    going = True
    for k, i in enumerate(order):
        thresholds[i] = alpha / (m - k)
        going = going and p_values[i] <= thresholds[i]
        rejected[i] = going
    return rejected, thresholds


def min_detectable_shift(
    spread: Sequence[float],
    alpha: float,
    power: float = 0.8,
    n_pairs: int | None = None,
    resamples: int = 400,
    seed: int = 0,
) -> float | None:
    """The smallest shift ``delta`` such that paired differences drawn from ``spread + delta`` (``spread``: the
    differences of an unchanged stack, e.g. the baseline against a perturbed run) make the one-sided signed-rank test
    reject at ``alpha`` with probability >= ``power``, with ``n_pairs`` pairs (default: as many as ``spread``).

    Found by bisection on a bootstrap estimate of the power. None when even an infinite shift cannot reject, i.e.
    when ``min_attainable_p(n_pairs) > alpha``.
    """
    d = np.asarray(spread, float)
    n = int(n_pairs or d.size)
    if d.size == 0 or min_attainable_p(n) > alpha:
        return None
    rng = np.random.default_rng(seed)
    draws = d[rng.integers(0, d.size, size=(resamples, n))]

    def power_at(delta: float) -> float:
        return float(np.mean(_signed_rank_p_rows(draws + delta) <= alpha))

    scale = float(np.max(np.abs(d))) if np.any(d) else 0.0
    lo, hi = 0.0, max(scale, 1e-6)
    while power_at(hi) < power:
        hi *= 2
        if hi > 1e6:
            return None
    if power_at(lo) >= power:
        return 0.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if power_at(mid) >= power else (mid, hi)
        if hi - lo <= 1e-3 * max(hi, 1e-9):
            break
    return hi
