"""`rover-sim bench rocks`: rock-based cross-site localisation on the ``rock_localization`` scenario.

The rover starts at the first site and drives to the others with the runner's VO-corrected goto (dead reckoning and
VO are both measured on this drive: the runner keeps a wheel/IMU dead reckoner beside the VO-corrected one). At
every site it takes a navcam stereo panorama; rocks are extracted and modelled, matched between every two sites up to
26 m apart, and the chain of sites is adjusted (:mod:`rover_sim.apps.survey`, :mod:`nav.rocks`). Figures against the
terrain's rock list and the simulator's true poses:

* extraction: recall of generated rocks taller than 20 cm within 30 m of each site, precision of the extracted
  rocks within 30 m (summed over the sites);
* modelling: median model RMS and model-type agreement of those rocks: the chosen model type against the generating
  shape, as a confusion matrix, by range band, overall and over the *well-observed* rocks, which the estimator
  itself marks from its own data (at least 200 points over at least 180 degrees of azimuth, range noise at most 15 %
  of the rock's height; :meth:`nav.rocks.RockObservation.well_observed`). The acceptance gate is on the
  well-observed rocks, >= 0.8: a 20-30 cm rock's four models differ by one or two centimetres, below the range noise
  of a distant or thinly seen rock, so there the type is a guess the data cannot settle (the overall figure is
  printed beside it), and a semi-ellipsoid of aspect near 1 is a hemispheroid to any data, so 1.0 is not reachable
  even on well-observed rocks (the generator draws semi-ellipsoid aspects uniformly from 1 to 1.5);
* matching: fraction of matches between the same generated rock, over all site pairs up to 26 m apart, and the
  site-to-site position error in % of the separation (worst pair);
* chain: mean position error over the sites after the first, dead reckoning vs VO vs adjusted (the pose-graph
  fusion of the VO legs and the rock transforms, :class:`nav.rocks.SiteChain`);
* by rock class (``--irregular-fraction``: that fraction of the generated rocks are irregular,
  :mod:`terrains.rock_shapes`, outside the four models): recall, precision and median model RMS separately for the
  analytic and the irregular rocks. An extracted rock counts for the class of the generated rock it is associated
  with; a false one for the class of the nearest generated rock. Model-type agreement is over analytic rocks only.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from nav.epipolar import EpipolarCheck
from nav.rocks import ROCK_SHAPES
from rover_sim.apps.survey import RangeCalibration, RockSiteSurvey, SurveyConfig, adjust_chain, calibrate_range_bias
from rover_sim.apps.survey_eval import (
    ExtractionEval,
    MatchEval,
    associate,
    evaluate_chain,
    evaluate_extraction,
    evaluate_match,
    rocks_in_true_frame,
)
from rover_sim.runtime.acceptance import bars
from rover_sim.scenario.loading import load_scenario
from terrains import Terrain, rock_class

SCENARIO = "rock_localization"
MAX_MATCH_SEPARATION_M = 26.0
ACCEPT = dataclasses.asdict(bars.ROCKS)  # the bars live in rover_sim.runtime.acceptance
NAVCAM_BASELINE_M = 0.2  # for reporting the fitted bias as a toe-in angle


def bench_rocks(
    json_path: str | None = None,
    scenario: str = SCENARIO,
    config: SurveyConfig = SurveyConfig(),
    seed: int | None = None,
    irregular_fraction: float | None = None,
    profile: str | None = None,
) -> dict:
    """Run the survey, print the markdown tables, write ``json_path`` (if given) and return the results.
    ``seed`` replaces the scenario's (another rock field along the same legs: a held-out check);
    ``irregular_fraction`` replaces ``terrain.rocks.irregular_fraction`` (irregular rocks mixed in);
    ``profile`` replaces ``sensors.profile`` ("flight" or "ideal"; the panoramas, the drive's VO and dead
    reckoning all follow it)."""
    t0 = time.perf_counter()
    sc = load_scenario(scenario, [f'sensors.profile="{profile}"'] if profile is not None else None, seed=seed)
    if irregular_fraction is not None:
        rocks = sc.terrain.rocks.model_validate(
            sc.terrain.rocks.model_dump() | {"irregular_fraction": irregular_fraction}
        )
        sc = sc.model_copy(update={"terrain": sc.terrain.model_copy(update={"rocks": rocks})})

    def progress(msg: str) -> None:
        print(f"  [{time.perf_counter() - t0:6.0f} s] {msg}", flush=True)

    with RockSiteSurvey(sc, config, progress=progress) as sv:
        sites = sv.run()
        terrain = sv.terrain
        focal = _focal_check(sv.focal_check)
    wall_survey = time.perf_counter() - t0

    # ground processing: the panorama pair's range bias, fitted on the rocks matched between sites
    raw_sites = sites
    sites, range_cal = calibrate_range_bias(raw_sites)
    raw_total = _sum([evaluate_extraction(s, terrain) for s in raw_sites])
    # extraction and modelling
    per_site = [evaluate_extraction(s, terrain) for s in sites]
    total = per_site[0]
    for e in per_site[1:]:
        total = total + e
    # matching: every pair of sites within 26 m (estimated), as the chain does
    chain = adjust_chain(sites)
    pairs: list[MatchEval] = []
    for (i, j), m in sorted(chain.matches.items()):
        pairs.append(evaluate_match(sites[i], sites[j], m, terrain))
    tried = [
        (i, j)
        for i in range(len(sites))
        for j in range(i + 1, len(sites))
        if np.linalg.norm(sites[i].T_world_rover_onboard[:2, 3] - sites[j].T_world_rover_onboard[:2, 3])
        <= MAX_MATCH_SEPARATION_M
    ]
    ce = evaluate_chain(sites, chain)
    n_match = sum(p.n_matches for p in pairs)
    result = {
        "recall": total.recall,
        "precision": total.precision,
        "median_rms_m": float(np.median(total.rms_m)) if total.rms_m else float("nan"),
        "match_correct_frac": sum(p.n_correct for p in pairs) / n_match if n_match else float("nan"),
        "site_error_pct": max((p.error_pct for p in pairs), default=float("nan")),
        "chain_error_m": {
            "dead_reckoning": float(np.mean(ce.dead_reckoning[1:])),
            "vo": float(np.mean(ce.vo[1:])),
            "adjusted": float(np.mean(ce.adjusted[1:])),
        },
        "model_type_match_frac": _analytic_frac(total, well_only=False),
        "model_type_match_frac_well_observed": _well_observed_frac(total),
        # extras
        "range_bias": _range_bias(range_cal, raw_total, raw_sites, terrain),
        "focal_check": focal,
        "profile": sc.sensors.profile,
        "irregular_fraction": sc.terrain.rocks.irregular_fraction,
        "by_rock_class": _by_class(sites, terrain),
        "model_type_count": int(np.sum(_analytic(total))),
        "model_type_well_observed_count": int(np.sum(_analytic(total) & np.asarray(total.well_observed, bool))),
        "model_type_match_by_range": _by_range(total),
        "model_type_confusion": _confusion(total.shapes),
        "model_type_confusion_well_observed": _confusion(
            [s for s, w in zip(total.shapes, total.well_observed, strict=True) if w]
        ),
        "chain_final_error_m": {
            "dead_reckoning": float(ce.dead_reckoning[-1]),
            "vo": float(ce.vo[-1]),
            "adjusted": float(ce.adjusted[-1]),
            "adjusted_incremental": float(ce.adjusted_incremental[-1]),
        },
        "chain_errors_per_site_m": {
            "dead_reckoning": ce.dead_reckoning.tolist(),
            "vo": ce.vo.tolist(),
            "adjusted": ce.adjusted.tolist(),
            "adjusted_incremental": ce.adjusted_incremental.tolist(),
        },
        "site_pairs": [
            {
                "sites": [p.site_a, p.site_b],
                "separation_m": p.separation_m,
                "matches": p.n_matches,
                "correct": p.n_correct,
                "error_pct": p.error_pct,
                "odometry_error_pct": 100.0 * p.odometry_error_m / p.separation_m,
            }
            for p in pairs
        ],
        "site_pairs_without_match": [list(t) for t in tried if t not in chain.matches],
        "sites": [
            {
                "recall": e.recall,
                "precision": e.precision,
                "n_rocks": len(s.rocks),
                "n_points": s.n_points,
                "timings_s": {k: round(v, 1) for k, v in s.timings_s.items()},
            }
            for s, e in zip(sites, per_site, strict=True)
        ],
        "chain_odometry": "measured: runner goto drive, wheel/IMU dead reckoning and VO-corrected onboard estimate",
        "wall_s": time.perf_counter() - t0,
        "survey_wall_s": wall_survey,
    }
    result["passed"] = passes(result)
    _print(result, per_site, pairs)
    if json_path:
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        Path(json_path).write_text(json.dumps(result, indent=2))
    return result


def _sum(evals: list[ExtractionEval]) -> ExtractionEval:
    total = evals[0]
    for e in evals[1:]:
        total = total + e
    return total


def _focal_check(check: EpipolarCheck | None) -> dict | None:
    """The panoramas' full-resolution epipolar check (``SurveyConfig.focal_check``): the right navcam's fitted
    relative focal length, pitch and roll, and the row disparities of its corners before and after (None: not run,
    the ideal profile)."""
    if check is None or check.fit is None:
        return None
    fit = check.fit
    return {
        "focal_length_pct": 100.0 * fit.scale,
        "pitch_mrad": 1e3 * float(fit.rotation_rad[0]),
        "roll_mrad": 1e3 * float(fit.rotation_rad[2]),
        "corners": fit.n_matches,
        "row_disparity_px": {"before": fit.before_px, "after": fit.after_px},
    }


def _range_bias(cal: RangeCalibration, raw_total: ExtractionEval, raw_sites: list, terrain: Terrain) -> dict:
    """The range-bias self-calibration (fitted inverse-range bias, as a toe-in on the navcams' 20 cm baseline) and
    the extraction figures without it (the rocks as the panoramas gave them)."""
    fit = cal.fit
    return {
        "applied": cal.applied,
        "beta_per_m": None if fit is None else fit.beta_per_m,
        "toe_in_mrad_at_0_2_m": None if fit is None else 1e3 * fit.toe_in_rad(NAVCAM_BASELINE_M),
        "range_error_at_25_m_m": None if fit is None else fit.range_error_m(25.0),
        "site_pairs": None if fit is None else fit.n_pairs,
        "tie_points": None if fit is None else fit.n_tie_points,
        "cost_drop": None if fit is None else fit.cost_at_zero - fit.cost_at_fit,
        "uncorrected": {
            "recall": raw_total.recall,
            "precision": raw_total.precision,
            "median_rms_m": float(np.median(raw_total.rms_m)) if raw_total.rms_m else float("nan"),
            "by_rock_class": _by_class(raw_sites, terrain),
        },
    }


def _by_class(sites: list, terrain: Terrain, max_range_m: float = 30.0, min_height_m: float = 0.2) -> dict:
    """Recall, precision and median model RMS per rock class ("analytic", "irregular"), summed over the sites (the
    same targets and association as :func:`rover_sim.apps.survey_eval.evaluate_extraction`)."""
    truth = terrain.rocks
    classes = np.array([rock_class(r) for r in truth])
    txy = np.array([[r.x_m, r.y_m] for r in truth]).reshape(-1, 2)
    counts = {
        c: {"n_true": 0, "n_found": 0, "n_extracted": 0, "n_correct": 0, "rms_m": []} for c in ("analytic", "irregular")
    }
    for site in sites:
        idx = associate(site, truth)
        cam = site.T_world_rover_true[:2, 3]
        t_range = np.linalg.norm(txy - cam, axis=1)
        target = (t_range <= max_range_m) & np.array([r.height_m > min_height_m for r in truth])
        found = {int(i) for i in idx if i >= 0}
        for i in np.flatnonzero(target):
            counts[classes[i]]["n_true"] += 1
            counts[classes[i]]["n_found"] += int(int(i) in found)
        est = rocks_in_true_frame(site)
        for k, i in enumerate(idx):
            if np.linalg.norm(est[k, :2] - cam) > max_range_m:
                continue
            nearest = i if i >= 0 else int(np.argmin(np.linalg.norm(txy - est[k, :2], axis=1)))
            c = counts[classes[nearest]]
            c["n_extracted"] += 1
            c["n_correct"] += int(i >= 0)
            if i >= 0 and target[i]:
                c["rms_m"].append(float(site.rocks[k].model.rms_m))
    out = {}
    for name, c in counts.items():
        out[name] = {
            "recall": c["n_found"] / c["n_true"] if c["n_true"] else float("nan"),
            "precision": c["n_correct"] / c["n_extracted"] if c["n_extracted"] else float("nan"),
            "median_rms_m": float(np.median(c["rms_m"])) if c["rms_m"] else float("nan"),
            "n_true": c["n_true"],
            "n_found": c["n_found"],
            "n_extracted": c["n_extracted"],
            "n_correct": c["n_correct"],
        }
    return out


def _analytic(e: ExtractionEval) -> np.ndarray:
    """Which of the evaluated rocks were generated by one of the four analytic shapes (model type is defined)."""
    return np.array([true in ROCK_SHAPES for true, _ in e.shapes], dtype=bool).reshape(-1)


def _analytic_frac(e: ExtractionEval, well_only: bool) -> float:
    sel = _analytic(e) & (np.asarray(e.well_observed, bool) if well_only else True)
    t = np.asarray(e.type_match, dtype=bool)[sel]
    return float(np.mean(t)) if t.size else float("nan")


def _by_range(e: ExtractionEval) -> dict[str, float]:
    r = np.asarray(e.range_m)[_analytic(e)]
    t = np.asarray(e.type_match, dtype=float)[_analytic(e)]
    out = {}
    for lo, hi in ((0, 10), (10, 20), (20, 30)):
        sel = (r >= lo) & (r < hi)
        out[f"{lo}-{hi} m"] = float(t[sel].mean()) if sel.any() else float("nan")
    return out


def _well_observed_frac(e: ExtractionEval) -> float:
    return _analytic_frac(e, well_only=True)


def _confusion(shapes: list[tuple[str, str]]) -> list[list[int]]:
    """Rows: generating shape, columns: chosen model, both in ``ROCK_SHAPES`` order."""
    m = np.zeros((len(ROCK_SHAPES), len(ROCK_SHAPES)), dtype=int)
    for true, chosen in shapes:
        if true in ROCK_SHAPES:  # irregular rocks have no model type
            m[ROCK_SHAPES.index(true), ROCK_SHAPES.index(chosen)] += 1
    return m.tolist()


def passes(result: dict) -> bool:
    return bars.rocks_verdict(result).passed


def _print(result: dict, per_site: list[ExtractionEval], pairs: list[MatchEval]) -> None:
    print(f"sensor profile: {result['profile']}\n")
    print("| figure | measured | acceptance | ok |")
    print("|---|---:|---|---|")
    for chk in bars.rocks_verdict(result).checks:  # the one judge (the JSON's passed, the JUnit cases too)
        print(f"| {chk.name} | {chk.measured} | {chk.bar} | {chk.cell()} |")
    by = result["model_type_match_by_range"]
    print(f"| model type = generating shape, all ({result['model_type_count']}) | "
          f"{result['model_type_match_frac']:.2f} (0-10 m {by['0-10 m']:.2f}, 10-20 m {by['10-20 m']:.2f}, "
          f"20-30 m {by['20-30 m']:.2f}) | (reported) | - |")  # fmt: skip
    print(f"\nwell-observed rocks: {result['model_type_well_observed_count']}; recall counts rocks > 20 cm within "
          "30 m, precision extracted rocks within 30 m, matches pairs <= 26 m apart; site-to-site error: worst pair; "
          "chain: mean site error DR / VO / adjusted")  # fmt: skip
    rb = result["range_bias"]
    if rb["beta_per_m"] is not None:
        raw = rb["uncorrected"]
        print(f"\nrange-bias self-calibration: beta {1e3 * rb['beta_per_m']:+.3f} /km (toe-in "
              f"{rb['toe_in_mrad_at_0_2_m']:+.3f} mrad on 20 cm; {rb['range_error_at_25_m_m']:+.2f} m at 25 m) from "
              f"{rb['tie_points']} tie points in {rb['site_pairs']} site pairs, cost drop {rb['cost_drop']:.1f}: "
              f"{'applied' if rb['applied'] else 'not significant, not applied'}; without it recall "
              f"{raw['recall']:.3f}, precision {raw['precision']:.3f}")  # fmt: skip
    fc = result["focal_check"]
    if fc is not None:
        rows = fc["row_disparity_px"]
        print(f"panorama epipolar check: right navcam focal length {fc['focal_length_pct']:+.3f} %, pitch "
              f"{fc['pitch_mrad']:+.3f} mrad, roll {fc['roll_mrad']:+.3f} mrad from {fc['corners']} corners; row "
              f"disparity {rows['before']:.3f} -> {rows['after']:.3f} px")  # fmt: skip
    print()
    print(f"| rock class (irregular fraction {result['irregular_fraction']:g}) | recall | precision | "
          "median model RMS |")  # fmt: skip
    print("|---|---:|---:|---:|")
    for name, c in result["by_rock_class"].items():
        print(f"| {name} | {c['recall']:.3f} ({c['n_found']}/{c['n_true']}) | {c['precision']:.3f} "
              f"({c['n_correct']}/{c['n_extracted']}) | {100 * c['median_rms_m']:.2f} cm |")  # fmt: skip
    print()
    short = [name.replace("_", "-") for name in ROCK_SHAPES]
    for title, key in (("all", "model_type_confusion"), ("well-observed", "model_type_confusion_well_observed")):
        print(f"| generating \\ chosen ({title}) | " + " | ".join(short) + " |")
        print("|---|" + "---:|" * len(short))
        for name, row in zip(short, result[key], strict=True):
            print(f"| {name} | " + " | ".join(str(v) for v in row) + " |")
        print()
    print("| site | rocks | recall | precision | points | render s | stereo s | extract s |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for k, (s, e) in enumerate(zip(result["sites"], per_site, strict=True)):
        t = s["timings_s"]
        print(f"| {k} | {s['n_rocks']} | {e.n_found}/{e.n_true} | {e.n_correct}/{e.n_extracted} | {s['n_points']} "
              f"| {t.get('render', 0):.0f} | {t.get('stereo', 0):.0f} | {t.get('extract', 0):.0f} |")  # fmt: skip
    print()
    print("| sites | separation (m) | matches | correct | error (% of sep.) | odometry error (% of sep.) |")
    print("|---|---:|---:|---:|---:|---:|")
    for p in pairs:
        print(f"| {p.site_a}-{p.site_b} | {p.separation_m:.1f} | {p.n_matches} | {p.n_correct} | {p.error_pct:.2f} "
              f"| {100 * p.odometry_error_m / p.separation_m:.2f} |")  # fmt: skip
    if result["site_pairs_without_match"]:
        print(f"\nsite pairs within 26 m without a match: {result['site_pairs_without_match']}")
    print()
    per = result["chain_errors_per_site_m"]
    print("| site | DR error (m) | VO error (m) | adjusted (m) | adjusted when added (m) |")
    print("|---:|---:|---:|---:|---:|")
    for k in range(len(per["vo"])):
        print(f"| {k} | {per['dead_reckoning'][k]:.3f} | {per['vo'][k]:.3f} | {per['adjusted'][k]:.3f} "
              f"| {per['adjusted_incremental'][k]:.3f} |")  # fmt: skip
    print(f"\nDR and VO are measured on the drive ({result['chain_odometry']}); wall {result['wall_s']:.0f} s.")
