"""The statistical regression gate of ``bench suite``: per-seed figures against a baseline's on the same seeds.

A baseline (``benchmarks/suite_baseline.json``, or the user's own file) stores, per gated scenario and metric, the
value on every gate seed, the environment it was recorded in, and the same figures from a second run of the same
code under a seeded perturbation of the initial state (``physics.perturb_size``): the spread another machine would
show. The gate pairs the current run with the baseline seed by seed; the test, its family-wise control and the
effect-size floors are :data:`rover_sim.runtime.acceptance.GATE` (the one judge); the minimum detectable change
is computed from the baseline's perturbed spread with the same test
(:func:`rover_sim.bench.stats.min_detectable_shift`), never from identical replays.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from rover_sim.bench import stats
from rover_sim.errors import ConfigError
from rover_sim.runtime import acceptance
from rover_sim.runtime.acceptance import GATE, GateMetric

BASELINE_FORMAT = "rover-sim suite baseline 2"
PerSeed = dict[int, float | None]  # seed -> value (None: not measured on that seed)


@dataclass(frozen=True)
class Baseline:
    profile: str
    seeds: tuple[int, ...]
    environment: dict
    perturbation: dict | None  # {"size": EPS, "seed": K} of the spread run, or None
    values: dict[str, dict[str, PerSeed]]  # scenario -> metric -> per seed
    perturbed: dict[str, dict[str, PerSeed]]  # the same, from the perturbed run of the same code

    def to_json(self) -> dict:
        def enc(t: dict[str, dict[str, PerSeed]]) -> dict:
            return {sc: {k: {str(s): v for s, v in per.items()} for k, per in m.items()} for sc, m in t.items()}

        scenarios = {sc: {"per_seed": enc(self.values)[sc], "perturbed": enc(self.perturbed).get(sc, {})}
                     for sc in sorted(self.values)}  # fmt: skip
        return {"format": BASELINE_FORMAT, "profile": self.profile, "seeds": list(self.seeds),
                "environment": self.environment, "perturbation": self.perturbation, "scenarios": scenarios}  # fmt: skip


def load_baseline(path: Path) -> Baseline:
    """Read a baseline file; an older format or a broken file is a one-line :class:`ConfigError`."""
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ConfigError(str(path), "(file)", "no such baseline file (record one with --update-baseline)") from None
    except OSError as e:
        raise ConfigError(str(path), "(file)", f"cannot read the baseline: {e.strerror or e}") from None
    except ValueError as e:
        raise ConfigError(str(path), "(syntax)", f"not valid JSON: {e}") from None
    if not isinstance(data, dict) or data.get("format") != BASELINE_FORMAT:
        raise ConfigError(str(path), "format", f"not a '{BASELINE_FORMAT}' file (per-seed values); record one "
                          "with `rover-sim bench suite --fast --update-baseline [--baseline PATH]`")  # fmt: skip

    def dec(t: dict) -> dict[str, PerSeed]:
        return {k: {int(s): v for s, v in per.items()} for k, per in t.items()}

    try:
        sc = data["scenarios"]
        return Baseline(str(data["profile"]), tuple(int(s) for s in data["seeds"]), dict(data.get("environment", {})),
                        data.get("perturbation"), {n: dec(v["per_seed"]) for n, v in sc.items()},
                        {n: dec(v.get("perturbed", {})) for n, v in sc.items()})  # fmt: skip
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise ConfigError(str(path), "scenarios", f"malformed baseline ({type(e).__name__}: {e})") from None


def save_baseline(baseline: Baseline, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(baseline.to_json(), indent=1, sort_keys=True) + "\n")


@dataclass(frozen=True)
class Regression:
    """One gated scenario x metric: the median paired change (current - baseline, in the metric's units and
    relative), the test's p and Holm threshold, the smallest p the test can reach with these pairs, the minimum
    detectable relative change (80 % power at the strictest Holm threshold, from the perturbed spread; at least the
    effect-size floor), and the verdict."""

    delta_median: float
    delta_median_rel: float | None
    p_value: float
    threshold: float
    n_pairs: int
    min_attainable_p: float
    min_detectable_rel: float | None
    regressed: bool

    def as_json(self) -> dict:
        return asdict(self)


def _transform(metric: GateMetric, v: np.ndarray) -> np.ndarray:
    return np.log(np.maximum(v, 0.0) + metric.offset) if metric.scale == "log" else v


def paired_differences(metric: GateMetric, current: PerSeed, base: PerSeed) -> tuple[list[int], np.ndarray]:
    """Seeds measured in both, and the differences in the metric's scale, oriented so that positive is worse."""
    seeds = sorted(s for s in current if current[s] is not None and base.get(s) is not None)
    if not seeds:
        return [], np.zeros(0)
    c = _transform(metric, np.array([current[s] for s in seeds], float))
    b = _transform(metric, np.array([base[s] for s in seeds], float))
    d = c - b
    return seeds, (-d if metric.worse == "lower" else d)


def baseline_tests(baseline: Baseline) -> int:
    """How many scenario x metric tests a gate against ``baseline`` makes at most: the Holm family."""
    return sum(1 for per in baseline.values.values() for m in GATE.metrics
               if any(v is not None for v in per.get(m.key, {}).values()))  # fmt: skip


def check_power(n_seeds: int, n_tests: int) -> None:
    """Refuse a gate that could never reject: the smallest attainable p must be below the strictest threshold."""
    strictest = GATE.alpha / max(n_tests, 1)
    if stats.min_attainable_p(n_seeds, "two-sided") > strictest:
        raise ConfigError("--seeds", str(n_seeds), f"the gate's {n_tests} tests at family-wise {GATE.alpha:g} need "
                          f"p <= {strictest:.2g}; {n_seeds} paired seeds reach at best "
                          f"{stats.min_attainable_p(n_seeds, 'two-sided'):.2g} (use more seeds)")  # fmt: skip


def compare(
    current: dict[str, dict[str, PerSeed]], baseline: Baseline, replayed: bool = False
) -> dict[str, dict[str, Regression]]:
    """Every gated scenario x metric of ``current`` (scenario -> metric -> per seed) against ``baseline``. For a VO
    replayed on the baseline stack's inputs (``replayed``) the family holds only the metrics an estimator can change
    (``GateMetric.estimator``): dead reckoning and the route are the recorded run's by construction."""
    tests: list[tuple[str, GateMetric, list[int], np.ndarray]] = []
    for sc, metrics in current.items():
        base = baseline.values.get(sc)
        if base is None:
            continue
        for m in GATE.metrics:
            if replayed and not m.estimator:
                continue
            if m.key not in base or m.key not in metrics:
                continue
            seeds, d = paired_differences(m, metrics[m.key], base[m.key])
            if len(seeds) >= GATE.min_pairs:
                tests.append((sc, m, seeds, d))
    pvals = [stats.signed_rank_p(d, "two-sided" if m.two_sided else "greater") for _, m, _, d in tests]
    _, thresholds = acceptance_holm(pvals)
    strictest = GATE.alpha / max(len(tests), 1)
    out: dict[str, dict[str, Regression]] = {}
    for (sc, m, seeds, d), p, thr in zip(tests, pvals, thresholds, strict=True):
        effect = float(np.median(d))
        base_vals = np.array([baseline.values[sc][m.key][s] for s in seeds], float)
        cur_vals = np.array([current[sc][m.key][s] for s in seeds], float)
        delta = float(np.median(cur_vals - base_vals))
        rel = (math.expm1(effect) * (1 if m.worse == "higher" else -1) if m.scale == "log"
               else (delta / abs(float(np.median(base_vals))) if np.median(base_vals) else None))  # fmt: skip
        n_nonzero = int(np.sum(np.abs(d) > 1e-12))
        out.setdefault(sc, {})[m.key] = Regression(
            delta_median=round(delta, 6),
            delta_median_rel=None if rel is None else round(rel, 6),
            p_value=p,
            threshold=thr,
            n_pairs=len(seeds),
            min_attainable_p=stats.min_attainable_p(len(seeds), "two-sided" if m.two_sided else "greater"),
            min_detectable_rel=min_detectable_rel(m, baseline, sc, len(seeds), strictest),
            regressed=acceptance.regressed(p, thr, effect, m) and n_nonzero > 0,
        )
    return out


def acceptance_holm(pvals: list[float]) -> tuple[list[bool], list[float]]:
    return stats.holm(pvals, GATE.alpha)


def min_detectable_rel(
    metric: GateMetric, baseline: Baseline, scenario: str, n_pairs: int, alpha: float
) -> float | None:
    """The smallest relative change of ``metric`` the gate detects with 80 % power at ``alpha``, from the spread
    between the baseline and its perturbed run (None when the baseline has no perturbed run); never below the
    metric's effect-size floor (a smaller change is not flagged however significant)."""
    pert = baseline.perturbed.get(scenario, {}).get(metric.key)
    base = baseline.values.get(scenario, {}).get(metric.key)
    if not pert or not base:
        return None
    _, spread = paired_differences(metric, pert, base)
    if spread.size < GATE.min_pairs:
        return None
    alt_alpha = alpha / 2 if metric.two_sided else alpha
    shift = stats.min_detectable_shift(spread, alt_alpha, GATE.power, n_pairs=n_pairs)
    if shift is None:
        return None
    if metric.scale == "log":
        rel = math.expm1(shift)
    else:
        med = float(np.median([v for v in base.values() if v is not None]))
        rel = shift / abs(med) if med else math.inf
    floor = metric.floor if metric.scale == "log" else metric.floor / max(abs(float(np.median(
        [v for v in base.values() if v is not None]))), 1e-9)  # fmt: skip
    return round(max(rel, floor), 4)
