"""Scenario-driven benchmarks: `rover-sim bench vo` (issue cases) and `rover-sim bench suite` (the catalogue).

Each case is a full closed-loop mission (physics, rendering, sensors, nav stack), deterministic for its seed.
The suite compares every metric with the committed baseline (``benchmarks/suite_baseline.json``) and fails on a
scenario that misses its own pass criterion or on a regression past the tolerances below.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from rover_sim.bench import write_json
from rover_sim.mission.pipeline import Metrics, run_scenario
from rover_sim.mission.scenario import catalogue, load_scenario
from rover_sim.resources import suite_baseline_path

BASELINE = suite_baseline_path()
# regression tolerances against the baseline
VO_ERROR_SLACK_PCT = 0.5  # VO error may grow by this many percentage points (absolute)
CONVERGENCE_SLACK_PCT = 5.0  # VO convergence may drop by this many points

VO_CASES = {
    "msstb": "msstb_rock_course",
    "slope30m": "slope30m",
    "featureless": "meridiani_plains",
    "shadow": "sol235_shadow",
}


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return f"{v:.2f}" if isinstance(v, float) else str(v)


def bench_vo(json_path: str | None = None, out_root: Path = Path("runs/bench_vo")) -> dict:
    """The issue's VO cases; prints the table with the acceptance figures beside the measurements."""
    results: dict[str, dict] = {}
    for case, scenario in VO_CASES.items():
        m = run_scenario(scenario, out_root / case, record=False)
        results[case] = {
            "distance_m": m.distance_m,
            "dr_error_pct": m.dr_error_pct,
            "vo_error_pct": m.vo_error_pct,
            "vo_convergence_pct": m.vo_convergence_pct,
            "false_positives": m.false_positives,
            "max_slip_pct": m.max_slip_pct,
            "vo_step_ms_median": m.vo_step_ms_median,
            "passed": m.passed,
        }
    accept = {
        "msstb": "VO < 1 %, DR > 10 %, slip >= 50 %",
        "slope30m": "VO <= 1 %, convergence >= 97 %",
        "featureless": "0 false positives",
        "shadow": "0 false positives",
    }
    print(
        "| case | distance (m) | max slip (%) | DR error (%) | VO error (%) | VO convergence (%) | false pos. "
        "| VO ms/step | acceptance | pass |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|:-:|")
    for case, r in results.items():
        print(
            f"| {case} | {_fmt(r['distance_m'])} | {_fmt(r['max_slip_pct'])} | {_fmt(r['dr_error_pct'])} | "
            f"{_fmt(r['vo_error_pct'])} | {_fmt(r['vo_convergence_pct'])} | {r['false_positives']} | "
            f"{_fmt(r['vo_step_ms_median'])} | {accept[case]} | {'yes' if r['passed'] else 'NO'} |"
        )
    write_json(json_path, results)
    return results


def _regressions(m: Metrics, base: dict | None) -> list[str]:
    if not base:
        return []
    out = []
    if m.vo_error_pct is not None and base.get("vo_error_pct") is not None:
        if m.vo_error_pct > base["vo_error_pct"] + VO_ERROR_SLACK_PCT:
            out.append(f"VO error {m.vo_error_pct} % > baseline {base['vo_error_pct']} % + {VO_ERROR_SLACK_PCT}")
    if m.vo_convergence_pct is not None and base.get("vo_convergence_pct") is not None:
        if m.vo_convergence_pct < base["vo_convergence_pct"] - CONVERGENCE_SLACK_PCT:
            out.append(
                f"VO convergence {m.vo_convergence_pct} % < baseline {base['vo_convergence_pct']} % "
                f"- {CONVERGENCE_SLACK_PCT}"
            )
    if m.false_positives > base.get("false_positives", 0):
        out.append(f"{m.false_positives} VO false positives (baseline {base.get('false_positives', 0)})")
    return out


def bench_suite(
    json_path: str | None = None,
    fast: bool = False,
    out_root: Path = Path("runs/bench_suite"),
    update_baseline: bool = False,
    baseline_path: Path | None = None,
) -> tuple[list[dict], bool]:
    """Run the catalogue (``fast``: the CI subset); markdown table; (rows, ok). ``baseline_path``: default BASELINE."""
    names = [n for n in catalogue() if not fast or load_scenario(n).fast]
    baseline_path = Path(baseline_path) if baseline_path is not None else BASELINE
    baseline = json.loads(baseline_path.read_text()) if baseline_path.is_file() else {}
    rows, ok = [], True
    for name in names:
        m = run_scenario(name, out_root / name, record=False)
        regress = _regressions(m, baseline.get(name))
        row = m.deterministic_dict() | {"timing": m.timing, "regressions": regress}
        rows.append(row)
        ok &= m.passed and not regress
    print("| scenario | distance (m) | max slip (%) | DR error (%) | VO error (%) | VO convergence (%) | pass | note |")
    print("|---|---:|---:|---:|---:|---:|:-:|---|")
    for r in rows:
        good = r["passed"] and not r["regressions"]
        note = "; ".join(r["regressions"]) or r["reason"]
        print(
            f"| {r['scenario']} | {_fmt(r['distance_m'])} | {_fmt(r['max_slip_pct'])} | {_fmt(r['dr_error_pct'])} | "
            f"{_fmt(r['vo_error_pct'])} | {_fmt(r['vo_convergence_pct'])} | {'yes' if good else 'NO'} | {note} |"
        )
    write_json(json_path, rows)
    if update_baseline:
        keep = ("vo_error_pct", "vo_convergence_pct", "false_positives", "dr_error_pct", "max_slip_pct")
        merged = baseline | {r["scenario"]: {k: r[k] for k in keep} for r in rows}
        baseline_path.parent.mkdir(parents=True, exist_ok=True)
        baseline_path.write_text(json.dumps(merged, indent=2, sort_keys=True) + "\n")
    return rows, ok
