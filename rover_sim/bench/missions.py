"""Scenario-driven benchmarks: `rover-sim bench vo` (issue cases) and `rover-sim bench suite` (the catalogue).

Each case is a full closed-loop mission (physics, rendering, sensors, nav stack), deterministic for its seed.
The suite compares every metric with the committed baseline (``benchmarks/suite_baseline.json``) and fails on a
scenario that misses its own pass criterion or on a regression past the tolerances below.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from rover_sim import interrupts
from rover_sim.bench import write_json
from rover_sim.mission import acceptance
from rover_sim.mission.run import Metrics, run_scenario
from rover_sim.mission.scenario import Scenario, catalogue, load_scenario, plugin_overrides, scenario_from_dict
from rover_sim.resources import suite_baseline_path

BASELINE = suite_baseline_path()
# regression tolerances against the baseline
VO_ERROR_SLACK_PCT = 0.5  # VO error may grow by this many percentage points (absolute)
CONVERGENCE_SLACK_PCT = 5.0  # VO convergence may drop by this many points
REL_TOLERANCE = 0.10  # --baseline FILE: a metric may get this much worse, relative to the file's value
ABS_FLOOR_PCT = 0.05  # ... plus this (percentage points), so a baseline of 0 does not fail on noise

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


def _as_scenario(scenario: str | Scenario, overrides: list[str] | None = None) -> Scenario:
    if isinstance(scenario, Scenario):
        return scenario_from_dict(scenario.resolved_dict(), f"<{scenario.name}>", overrides) if overrides else scenario
    return load_scenario(scenario, overrides)


def _vo_case(scenario: str | Scenario, out_dir: Path, overrides: list[str]) -> dict:
    m = run_scenario(_as_scenario(scenario, overrides), out_dir, record=False)
    return {
        "distance_m": m.distance_m,
        "dr_error_pct": m.dr_error_pct,
        "vo_error_pct": m.vo_error_pct,
        "vo_convergence_pct": m.vo_convergence_pct,
        "false_positives": m.false_positives,
        "max_slip_pct": m.max_slip_pct,
        "vo_step_ms_median": m.vo_step_ms_median,
        "passed": m.passed,
        "reason": m.reason,
        "wall_s": m.wall_s,
    }


def _bar(total: int, desc: str):  # noqa: ANN202
    """A per-case progress bar on stderr (none when stderr is not a terminal)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="case", disable=None, leave=False)


def bench_vo(
    json_path: str | None = None,
    out_root: Path = Path("runs/bench_vo"),
    plugins: list[str] | None = None,
    cases: list[str] | None = None,
    case_scenarios: dict[str, str | Scenario] | None = None,
) -> dict:
    """The issue's VO cases with MER VO, then with each plugin VO (``plugins``: import paths or entry-point names);
    prints one table with the acceptance (each scenario's own ``[pass]``) beside the measurements.
    ``case_scenarios`` replaces the case list (case name -> scenario name or TOML path), e.g. for a quick check."""
    all_cases = case_scenarios if case_scenarios is not None else VO_CASES
    chosen = {c: s for c, s in all_cases.items() if cases is None or c in cases}
    jobs = [("MER VO (builtin)", None, case) for case in chosen]
    jobs += [(plugin, plugin, case) for plugin in plugins or [] for case in chosen]
    results: dict = {}
    runs: dict = {"MER VO (builtin)": results}
    with _bar(len(jobs), "bench vo") as bar:
        for vo_name, plugin, case in jobs:
            bar.set_postfix_str(f"{vo_name}: {case}")
            if plugin is None:
                per, r = results, _vo_case(chosen[case], out_root / case, [])
            else:
                per = results.setdefault("plugins", {}).setdefault(plugin, {})
                runs[plugin] = per
                r = _vo_case(chosen[case], out_root / "plugins" / plugin.replace(":", "_") / case,
                             plugin_overrides(vo=plugin))  # fmt: skip
            per[case] = r
            bar.update()
            if interrupts.was_interrupted(r["reason"]):
                break  # Ctrl-C / SIGTERM: report what ran (the CLI exits 130 / 143)
    print(
        "| VO | case | distance (m) | max slip (%) | DR error (%) | VO error (%) | VO convergence (%) | false pos. "
        "| VO ms/step | acceptance | pass |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---|:-:|")
    for vo_name, per in runs.items():
        for case, r in per.items():
            if case == "plugins":
                continue
            accept = acceptance.describe(_as_scenario(chosen[case]).passing)
            print(
                f"| {vo_name} | {case} | {_fmt(r['distance_m'])} | {_fmt(r['max_slip_pct'])} | "
                f"{_fmt(r['dr_error_pct'])} | {_fmt(r['vo_error_pct'])} | {_fmt(r['vo_convergence_pct'])} | "
                f"{r['false_positives']} | {_fmt(r['vo_step_ms_median'])} | {accept} | "
                f"{'yes' if r['passed'] else 'NO'} |"
            )
    write_json(json_path, results)
    return results


def all_passed(results: dict) -> bool:
    """Every case of the built-in and of every plugin met its criteria."""
    ok = all(r["passed"] for c, r in results.items() if c != "plugins")
    for per in results.get("plugins", {}).values():
        ok &= all(r["passed"] for r in per.values())
    return ok


def _regressions(m: Metrics, base: dict | None) -> list[str]:
    """Against the committed baseline: absolute slack on VO error and convergence, no new false positives."""
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


def relative_regressions(m: Metrics, base: dict | None, tolerance: float = REL_TOLERANCE) -> list[str]:
    """Against a user's baseline file: VO and DR error may grow, VO convergence drop, by ``tolerance`` of the
    baseline value (plus :data:`ABS_FLOOR_PCT`); no new false positives."""
    if not base:
        return []
    out = []
    for key, label in (("vo_error_pct", "VO error"), ("dr_error_pct", "DR error")):
        now, was = getattr(m, key), base.get(key)
        if now is not None and was is not None and now > was * (1 + tolerance) + ABS_FLOOR_PCT:
            out.append(f"{label} {now} % > baseline {was} % (+{100 * tolerance:g} %)")
    now, was = m.vo_convergence_pct, base.get("vo_convergence_pct")
    if now is not None and was is not None and now < was * (1 - tolerance) - ABS_FLOOR_PCT:
        out.append(f"VO convergence {now} % < baseline {was} % (-{100 * tolerance:g} %)")
    if m.false_positives > (base.get("false_positives") or 0):
        out.append(f"{m.false_positives} VO false positives (baseline {base.get('false_positives') or 0})")
    return out


def load_baseline(path: Path) -> dict:
    """A baseline file: ``{scenario: {metric: value}}`` (as ``--update-baseline`` writes it) or the ``--json``
    of an earlier ``bench suite`` run (a list of rows)."""
    from rover_sim.errors import ConfigError

    try:
        data = json.loads(Path(path).read_text())
    except OSError as e:
        raise ConfigError(str(path), "(file)", f"cannot read the baseline: {e.strerror or e}") from None
    except ValueError as e:
        raise ConfigError(str(path), "(syntax)", f"not valid JSON: {e}") from None
    if isinstance(data, list) and all(isinstance(r, dict) and "scenario" in r for r in data):
        return {r["scenario"]: r for r in data}
    if isinstance(data, dict) and all(isinstance(v, dict) for v in data.values()):
        return data
    raise ConfigError(str(path), "(top level)", "expected {scenario: {metric: value}} or a bench suite --json list")


def bench_suite(
    json_path: str | None = None,
    fast: bool = False,
    out_root: Path = Path("runs/bench_suite"),
    update_baseline: bool = False,
    overrides: list[str] | None = None,
    label: str = "builtin",
    baseline_path: Path | None = None,
    tolerance: float = REL_TOLERANCE,
) -> tuple[list[dict], bool]:
    """Run the catalogue (``fast``: the CI subset), with ``overrides`` (e.g. a plugin VO); markdown table;
    (rows, ok). The committed baseline's regression check applies to the built-in stack only
    (``label == "builtin"``); a ``baseline_path`` (the user's own) is checked with relative ``tolerance`` for any
    stack, and ``update_baseline`` then writes that file. Ctrl-C / SIGTERM stops after the interrupted scenario."""
    names = [n for n in catalogue() if not fast or load_scenario(n).fast]
    own = baseline_path is not None
    store = Path(baseline_path) if own else BASELINE
    baseline = load_baseline(store) if own and store.is_file() else ({} if own else _committed())
    if own and not store.is_file() and not update_baseline:
        from rover_sim.errors import ConfigError

        raise ConfigError(str(store), "(file)", "no such baseline file (create it with --update-baseline)")
    rows, ok = [], True
    with _bar(len(names), f"bench suite ({label})") as bar:
        for name in names:
            bar.set_postfix_str(name)
            m = run_scenario(name, out_root / label.replace(":", "_") / name, record=False, overrides=overrides or [])
            if own:
                regress = relative_regressions(m, baseline.get(name), tolerance)
            else:
                regress = _regressions(m, baseline.get(name)) if label == "builtin" else []
            row = m.deterministic_dict() | {"timing": m.timing, "regressions": regress}
            rows.append(row)
            ok &= m.passed and not regress
            bar.update()
            if interrupts.was_interrupted(m.reason):
                break
    print(f"stack: {label}")
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
    complete = not any(interrupts.was_interrupted(r["reason"]) for r in rows)
    if update_baseline and (label == "builtin" or own) and complete:
        keep = ("vo_error_pct", "vo_convergence_pct", "false_positives", "dr_error_pct", "max_slip_pct")
        merged = baseline | {r["scenario"]: {k: r[k] for k in keep} for r in rows}
        store.parent.mkdir(parents=True, exist_ok=True)
        store.write_text(json.dumps(merged, indent=2, sort_keys=True) + "\n")
    return rows, ok


def _committed() -> dict:
    return json.loads(BASELINE.read_text()) if BASELINE.is_file() else {}
