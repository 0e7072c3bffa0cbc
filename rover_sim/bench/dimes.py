"""`rover-sim bench dimes`: DIMES horizontal-velocity error over a Monte-Carlo of seeded descents.

Protocol: ``runs`` descents (:mod:`~mission.descent`), run ``k`` with conditions seed ``k`` (wind speed uniform in
0-20 m/s from a uniform direction, wind shear, parachute swing, spin, IMU and radar errors, sun) over terrain
seed ``k % terrains`` (``terrains`` cratered plains, default one per five descents: synthesising and texturing a
3.2 km plain takes about 10 s, rendering a descent about 0.5 s; each descent sees its own part of its plain from its
own heading). Each descent's three images go through :func:`nav.dimes.estimate_velocity`; the error is the
horizontal velocity estimate at the third image minus the truth. Then ``featureless_runs`` descents over a
featureless plain (:data:`rover_sim.apps.descent.FEATURELESS_TERRAIN`) must all be rejected (no estimate).

``velocity_error_1sigma_mps`` is the 68.27th percentile of the error *magnitude* over the accepted estimates (for a
2-D Gaussian error that is 1.5 times the per-axis sigma, so the figure is conservative); the RMS per-axis error is
reported beside it. Acceptance (:class:`rover_sim.runtime.bars.DimesBar`, judged by
:func:`~rover_sim.runtime.bars.dimes_verdict`): <= 1.5 m/s over >= 50 descents with winds up to 20 m/s, of
which >= 90 % give an accepted estimate, and the featureless case rejected. Rendering needs EGL; runs are
sequential in this process (never fork after a GL context exists).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

import rover_sim  # noqa: F401  (sets MUJOCO_GL before mujoco is imported)
from nav.dimes import DimesParams, DimesResult, estimate_velocity
from rover_sim.apps.descent import FEATURELESS_TERRAIN, DescentConditions, DescentRun, DescentWorld
from rover_sim.bench import write_json
from rover_sim.runtime.acceptance import bars

MAX_WIND_MPS = 20.0
WIND_BINS_MPS = (0.0, 5.0, 10.0, 15.0, 20.0)
FEATURELESS_SEED_OFFSET = 10_000  # conditions seeds of the featureless descents


@dataclass(frozen=True)
class DescentOutcome:
    seed: int
    terrain_seed: int
    wind_mps: float
    true_velocity_mps: tuple[float, float]
    estimate_mps: tuple[float, float] | None
    error_mps: float | None  # |estimate - truth|, None if rejected
    reason: str
    fire_tirs: bool
    fire_tirs_truth: bool
    estimate_ms: float
    render_s: float


def evaluate(run: DescentRun, result: DimesResult, params: DimesParams, render_s: float, seed: int) -> DescentOutcome:
    truth = run.truth.horizontal_velocity_mps
    est = result.velocity_mps
    return DescentOutcome(
        seed=seed,
        terrain_seed=run.terrain_seed,
        wind_mps=float(np.linalg.norm(run.conditions.wind_mps)),
        true_velocity_mps=(float(truth[0]), float(truth[1])),
        estimate_mps=None if est is None else (float(est[0]), float(est[1])),
        error_mps=None if est is None else float(np.linalg.norm(est - truth)),
        reason=result.reason,
        fire_tirs=result.fire_tirs,
        fire_tirs_truth=bool(np.linalg.norm(truth) > params.tirs_threshold_mps),
        estimate_ms=result.elapsed_ms,
        render_s=render_s,
    )


def run_descents(
    runs: int, terrains: int, params: DimesParams, max_wind_mps: float = MAX_WIND_MPS
) -> list[DescentOutcome]:
    outcomes = []
    for terrain_seed in range(terrains):
        seeds = [k for k in range(runs) if k % terrains == terrain_seed]
        if not seeds:
            continue
        with DescentWorld.build(terrain_seed) as world:
            for seed in seeds:
                t0 = time.perf_counter()
                run = world.fly(DescentConditions.sample(seed, max_wind_mps))
                render_s = time.perf_counter() - t0
                outcomes.append(evaluate(run, estimate_velocity(run.frames, params), params, render_s, seed))
    return sorted(outcomes, key=lambda o: o.seed)


def run_featureless(n: int, params: DimesParams) -> list[DescentOutcome]:
    out = []
    with DescentWorld.build(0, FEATURELESS_TERRAIN) as world:
        for k in range(n):
            seed = FEATURELESS_SEED_OFFSET + k
            t0 = time.perf_counter()
            run = world.fly(DescentConditions.sample(seed))
            render_s = time.perf_counter() - t0
            out.append(evaluate(run, estimate_velocity(run.frames, params), params, render_s, seed))
    return out


def _stats(rows: list[DescentOutcome]) -> dict:
    errs = np.array([o.error_mps for o in rows if o.error_mps is not None])
    vec = np.array([np.subtract(o.estimate_mps, o.true_velocity_mps) for o in rows if o.estimate_mps is not None])
    return {
        "runs": len(rows),
        "accepted": int(len(errs)),
        "sigma68": float(np.percentile(errs, 68.27)) if len(errs) else None,
        "rms_axis": float(np.sqrt(np.mean(vec**2))) if len(errs) else None,
        "mean": float(errs.mean()) if len(errs) else None,
        "max": float(errs.max()) if len(errs) else None,
        "tirs_ok": sum(o.fire_tirs == o.fire_tirs_truth for o in rows if o.error_mps is not None),
    }


def _f(x: float | None, fmt: str = ".2f") -> str:
    return "-" if x is None else format(x, fmt)


def bench_dimes(
    json_path: str | None = None,
    runs: int = 50,
    *,
    terrains: int | None = None,
    featureless_runs: int = 3,
    params: DimesParams | None = None,
) -> dict:
    """Monte-Carlo of ``runs`` seeded descents (and ``featureless_runs`` featureless ones); prints markdown tables,
    writes ``json_path`` if given, returns the result dict (``runs``, ``velocity_error_1sigma_mps``,
    ``featureless_rejected`` and extras)."""
    params = params or DimesParams()
    terrains = terrains or max(1, runs // 5)
    t0 = time.perf_counter()
    outcomes = run_descents(runs, terrains, params)
    featureless = run_featureless(featureless_runs, params)
    wall_s = time.perf_counter() - t0

    total = _stats(outcomes)
    featureless_rejected = all(o.estimate_mps is None for o in featureless)
    print(f"DIMES Monte-Carlo: {runs} descents over {terrains} terrains, winds 0-{MAX_WIND_MPS:.0f} m/s, "
          f"{params.features_per_image} features/image, images 256x256\n")  # fmt: skip
    print(
        "| wind (m/s) | descents | accepted | error 68 % (m/s) | RMS per axis (m/s) | mean (m/s) | max (m/s) "
        "| TIRS decision right |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for lo, hi in zip(WIND_BINS_MPS[:-1], WIND_BINS_MPS[1:], strict=True):
        s = _stats([o for o in outcomes if lo <= o.wind_mps < hi or (hi == WIND_BINS_MPS[-1] and o.wind_mps == hi)])
        print(
            f"| {lo:.0f}-{hi:.0f} | {s['runs']} | {s['accepted']} | {_f(s['sigma68'])} | {_f(s['rms_axis'])} | "
            f"{_f(s['mean'])} | {_f(s['max'])} | {s['tirs_ok']}/{s['accepted']} |"
        )
    print(
        f"| **all** | {total['runs']} | {total['accepted']} | **{_f(total['sigma68'])}** | {_f(total['rms_axis'])} "
        f"| {_f(total['mean'])} | {_f(total['max'])} | {total['tirs_ok']}/{total['accepted']} |"
    )
    rejected = [o for o in outcomes if o.estimate_mps is None]
    ms = np.array([o.estimate_ms for o in outcomes + featureless])
    result = {
        "runs": runs,
        "accepted": total["accepted"],
        "velocity_error_1sigma_mps": total["sigma68"],
        "featureless_rejected": featureless_rejected,
        "accepted_fraction": total["accepted"] / max(runs, 1),
        "velocity_error_rms_per_axis_mps": total["rms_axis"],
        "velocity_error_mean_mps": total["mean"],
        "velocity_error_max_mps": total["max"],
        "tirs_decisions_correct": total["tirs_ok"],
        "tirs_threshold_mps": params.tirs_threshold_mps,
        "ms_per_estimate_median": float(np.median(ms)) if len(ms) else None,
        "terrains": terrains,
        "features_per_image": params.features_per_image,
        "wall_s": wall_s,
        "descents": [asdict(o) for o in outcomes],
        "featureless": [asdict(o) for o in featureless],
    }
    verdict = bars.dimes_verdict(result)  # the one judge: this table, the JSON, the JUnit and the exit status
    result |= {"passed": verdict.passed, "reasons": verdict.reasons}
    print()
    print("| check | measured | acceptance | ok |")
    print("|---|---:|---|---|")
    for c in verdict.checks:
        print(f"| {c.name} | {c.measured} | {c.bar} | {c.cell()} |")
    print(
        f"\nfeatureless plain: {sum(o.estimate_mps is None for o in featureless)}/{len(featureless)} estimates "
        f"rejected ({', '.join(sorted({o.reason for o in featureless})) or '-'})"
    )
    if rejected:
        print(f"textured descents rejected: {len(rejected)} ({', '.join(sorted({o.reason for o in rejected}))})")
    if len(ms):
        print(f"DIMES time per estimate (median, this machine): {np.median(ms):.0f} ms")
    print(f"wall time (terrain synthesis + rendering + estimation): {wall_s:.0f} s")
    write_json(json_path, result)
    return result
