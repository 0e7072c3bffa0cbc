"""Scenario-driven benchmarks: `rover-sim bench vo` (issue cases) and `rover-sim bench suite` (the catalogue).

Each case is a full closed-loop mission (physics, rendering, sensors, nav stack), deterministic for its seed.
The suite compares every metric with the committed baseline (``benchmarks/suite_baseline.json``) and fails on a
scenario that misses its own pass criterion or on a regression past the tolerances below.

Sensor profiles (issue #16): benchmarks measure the ``flight`` profile (:data:`BENCH_PROFILE`) and, beside it,
the ``ideal`` one; every table and every JSON case says which. ``bench vo`` runs each case on flight, on ideal,
and on flight with the full-pose VO update (``--quick``: flight only). ``bench suite`` runs both profiles; with
``--fast`` (the CI gate) only the profile the committed baseline was recorded on (:data:`BASELINE_PROFILE`), so
the gate keeps its meaning and its few minutes. The regression gate always compares the run of
:data:`BASELINE_PROFILE` with the baseline, and ``--update-baseline`` stores that run.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path

from rover_sim import interrupts
from rover_sim.bench import write_json
from rover_sim.mission import acceptance
from rover_sim.mission.run import Metrics, run_scenario
from rover_sim.mission.scenario import Scenario, catalogue, load_scenario, plugin_overrides, scenario_from_dict
from rover_sim.mission.sensors_spec import Profile
from rover_sim.resources import suite_baseline_path

BASELINE = suite_baseline_path()
# regression tolerances against the baseline
# VO error may grow by VO_ERROR_REL (relative) or VO_ERROR_SLACK_PCT percentage points, whichever is larger;
# DR error and max slip may move by DR_SLIP_REL either way (they are physics: a change means the world changed)
VO_ERROR_REL = 0.25
VO_ERROR_SLACK_PCT = 0.1
DR_SLIP_REL = 0.10
DR_SLIP_FLOOR_PCT = 0.05  # ... plus this, so a near-zero value does not fail on rounding
CONVERGENCE_SLACK_PCT = 5.0  # VO convergence may drop by this many points
REL_TOLERANCE = 0.10  # --baseline FILE: a metric may get this much worse, relative to the file's value
ABS_FLOOR_PCT = 0.05  # ... plus this (percentage points), so a baseline of 0 does not fail on noise

BENCH_PROFILE: Profile = "flight"  # what the benchmarks measure first (issue #16)
BASELINE_PROFILE: Profile = "flight"  # the profile benchmarks/suite_baseline.json was recorded on

VO_CASES = {
    "msstb": "msstb_rock_course",
    "slope30m": "slope30m",
    "featureless": "meridiani_plains",
    "shadow": "sol235_shadow",
    "flat": "flat_benign",
}


def profile_overrides(profile: Profile) -> list[str]:
    """``--set`` overrides that select a sensor profile."""
    return [f'sensors.profile="{profile}"']


def _metres(v: float | None) -> str:
    """An RMS error in metres to the millimetre (``-`` when not measured)."""
    return "-" if v is None else f"{v:.3f}"


def _segments(d: dict | None) -> str:
    """``{"1m": a, "5m": b, "10m": c}`` as ``a / b / c`` (``-`` where the drive was too short)."""
    if not d:
        return "-"
    return " / ".join(_fmt(d.get(k)) for k in ("1m", "5m", "10m"))


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return f"{v:.2f}" if isinstance(v, float) else str(v)


def _as_scenario(scenario: str | Scenario, overrides: list[str] | None = None) -> Scenario:
    if isinstance(scenario, Scenario):
        return scenario_from_dict(scenario.resolved_dict(), f"<{scenario.name}>", overrides) if overrides else scenario
    return load_scenario(scenario, overrides)


def _vo_case(scenario: str | Scenario, out_dir: Path, overrides: list[str], profile: Profile = BENCH_PROFILE) -> dict:
    sc = _as_scenario(scenario, overrides + profile_overrides(profile))
    m = run_scenario(sc, out_dir, record=False)
    return {
        "profile": profile,
        "vo_update": sc.nav.vo.update,
        "kitti_segment_error_pct": m.kitti_segment_error_pct,
        "rms_position_error_m": m.rms_position_error_m,
        "vo_covariance_nees": m.extra.get("vo_covariance_nees"),
        "distance_m": m.distance_m,
        "dr_error_pct": m.dr_error_pct,
        "vo_error_pct": m.vo_error_pct,
        "vo_convergence_pct": m.vo_convergence_pct,
        "false_positives": m.false_positives,
        "vo_accepted": m.vo_accepted,
        "vo_refused_reasons": dict(m.vo_refused_reasons),
        "vo_refusals_justified": m.vo_refusals_justified,
        "pointing_changes": m.pointing_changes,
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
    quick: bool = False,
) -> dict:
    """The issue's VO cases with MER VO on the flight profile, then with each plugin VO (``plugins``: import paths
    or entry-point names); unless ``quick``, MER VO again on the ideal profile (top-level ``"ideal"``) and on the
    flight profile with the full-pose VO update (top-level ``"full_pose"``). Prints one table with the acceptance
    (each scenario's own ``[pass]``, judged on the flight run) beside the measurements.
    ``case_scenarios`` replaces the case list (case name -> scenario name or TOML path), e.g. for a quick check."""
    all_cases = case_scenarios if case_scenarios is not None else VO_CASES
    chosen = {c: s for c, s in all_cases.items() if cases is None or c in cases}
    builtin = "MER VO (builtin)"
    # (table label, result dict key path, profile, extra overrides)
    variants = [(builtin, (), BENCH_PROFILE, [])]
    if not quick:
        variants += [
            (builtin, ("ideal",), "ideal", []),
            (f"{builtin}, full-pose update", ("full_pose",), BENCH_PROFILE, ['nav.vo.update="full_pose"']),
        ]
    variants += [(p, ("plugins", p), BENCH_PROFILE, plugin_overrides(vo=p)) for p in plugins or []]
    jobs = [(v, case) for v in variants for case in chosen]
    results: dict = {}
    runs: list[tuple[str, dict]] = []
    with _bar(len(jobs), "bench vo") as bar:
        for (label, keys, profile, extra), case in jobs:
            bar.set_postfix_str(f"{label} ({profile}): {case}")
            per = results
            for k in keys:
                per = per.setdefault(k, {})
            if not runs or runs[-1][1] is not per:
                runs.append((label, per))
            sub = out_root.joinpath(*(k.replace(":", "_") for k in keys), case)
            r = _vo_case(chosen[case], sub, extra, profile)
            per[case] = r
            bar.update()
            if interrupts.was_interrupted(r["reason"]):
                break  # Ctrl-C / SIGTERM: report what ran (the CLI exits 130 / 143)
    print(
        "| VO | profile | VO update | case | distance (m) | max slip (%) | DR error (%) | VO error (%) "
        "| DR segments 1/5/10 m (%) | VO segments 1/5/10 m (%) | RMS DR / VO (m) | VO convergence (%) | false pos. "
        "| VO ms/step | acceptance | pass |"
    )
    print("|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|:-:|")
    for label, case, r in _table_rows(runs, chosen):
        accept = acceptance.describe(_as_scenario(chosen[case]).passing)
        seg, rms = r["kitti_segment_error_pct"], r["rms_position_error_m"]
        print(
            f"| {label} | {r['profile']} | {r['vo_update']} | {case} | {_fmt(r['distance_m'])} | "
            f"{_fmt(r['max_slip_pct'])} | {_fmt(r['dr_error_pct'])} | {_fmt(r['vo_error_pct'])} | "
            f"{_segments(seg.get('dead_reckoning'))} | {_segments(seg.get('vo'))} | "
            f"{_metres(rms.get('dead_reckoning'))} / {_metres(rms.get('vo'))} | {_fmt(r['vo_convergence_pct'])} | "
            f"{r['false_positives']} | {_fmt(r['vo_step_ms_median'])} | {accept} | "
            f"{acceptance.pass_cell(r['passed'], r['reason'])} |"
        )
    _print_nees(runs, chosen)
    write_json(json_path, results)
    return results


def _print_nees(runs: list[tuple[str, dict]], chosen: dict) -> None:
    """VO's covariance consistency per case (NEES medians: per accepted step and over 1 m and 5 m of consecutive
    steps; a consistent covariance gives about 2.37 everywhere)."""
    print(
        "\n| VO | profile | VO update | case | NEES per step | NEES over 1 m | NEES over 5 m | "
        "(consistent: median 2.37, 3 dof) |"
    )
    print("|---|---|---|---|---:|---:|---:|---|")
    for label, case, r in _table_rows(runs, chosen):
        n = r.get("vo_covariance_nees")
        if n is None:
            print(f"| {label} | {r['profile']} | {r['vo_update']} | {case} | - | - | - | no covariance |")
            continue
        seg = n["segment_median"]
        print(
            f"| {label} | {r['profile']} | {r['vo_update']} | {case} | {_fmt(n['step_median'])} | "
            f"{_fmt(seg.get('1m'))} | {_fmt(seg.get('5m'))} | |"
        )


def _table_rows(runs: list[tuple[str, dict]], chosen: dict) -> Iterator[tuple[str, str, dict]]:
    """(variant label, case, result) of every run case in the chosen set, in run order."""
    for label, per in runs:
        for case, r in per.items():
            if case in chosen:
                yield label, case, r


COMPARISON_KEYS = ("plugins", "ideal", "full_pose")  # bench vo top-level keys that are not flight cases


def all_passed(results: dict) -> bool:
    """Every case of the built-in and of every plugin met its criteria."""
    ok = all(r["passed"] for c, r in results.items() if c not in COMPARISON_KEYS)
    for per in results.get("plugins", {}).values():
        ok &= all(r["passed"] for r in per.values())
    return ok


def _regressions(m: Metrics, base: dict | None) -> list[str]:
    """Against the committed baseline, every stored metric: VO error +25 % relative or +0.1 pp (whichever is
    larger), DR error and max slip within +-10 %, VO convergence -5 points, no new false positives."""
    if not base:
        return []
    out = []
    if m.vo_error_pct is not None and base.get("vo_error_pct") is not None:
        was = base["vo_error_pct"]
        limit = was + max(VO_ERROR_REL * was, VO_ERROR_SLACK_PCT)
        if m.vo_error_pct > limit:
            out.append(f"VO error {m.vo_error_pct} % > baseline {was} % (limit {limit:.3f} %)")
    for key, label in (("dr_error_pct", "DR error"), ("max_slip_pct", "max slip")):
        now, was = getattr(m, key), base.get(key)
        if now is not None and was is not None and abs(now - was) > DR_SLIP_REL * abs(was) + DR_SLIP_FLOOR_PCT:
            out.append(f"{label} {now} % differs from baseline {was} % by more than {100 * DR_SLIP_REL:g} %")
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
        # rows of several profiles: keep the baseline profile's (older files have no "profile")
        return {r["scenario"]: r for r in data if r.get("profile", BASELINE_PROFILE) == BASELINE_PROFILE}
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
    profiles: tuple[Profile, ...] | None = None,
) -> tuple[list[dict], bool]:
    """Run the catalogue (``fast``: the CI subset), with ``overrides`` (e.g. a plugin VO), on each sensor profile of
    ``profiles`` (default: flight and ideal; with ``fast`` only :data:`BASELINE_PROFILE`); one markdown table per
    profile; (rows, ok), each row tagged with its ``"profile"``. The baseline gate judges the
    :data:`BASELINE_PROFILE` run only: the committed baseline's regression check applies to the built-in stack
    (``label == "builtin"``); a ``baseline_path`` (the user's own) is checked with relative ``tolerance`` for any
    stack, and ``update_baseline`` then writes that file. Ctrl-C / SIGTERM stops after the interrupted scenario."""
    if profiles is None:
        profiles = (BASELINE_PROFILE,) if fast else (BENCH_PROFILE, "ideal")
    profiles = tuple(dict.fromkeys(profiles))
    # sol-scale drives (a [sol] table: hundreds of metres on streamed terrain) are judged by `bench traverse`
    names = [n for n in catalogue() if (not fast or load_scenario(n).fast) and load_scenario(n).sol is None]
    own = baseline_path is not None
    store = Path(baseline_path) if own else BASELINE
    baseline = load_baseline(store) if own and store.is_file() else ({} if own else _committed())
    if own and not store.is_file() and not update_baseline:
        from rover_sim.errors import ConfigError

        raise ConfigError(str(store), "(file)", "no such baseline file (create it with --update-baseline)")
    rows, ok = [], True
    jobs = [(profile, name) for profile in profiles for name in names]
    with _bar(len(jobs), f"bench suite ({label})") as bar:
        for profile, name in jobs:
            bar.set_postfix_str(f"{profile}: {name}")
            out_dir = out_root / label.replace(":", "_") / profile / name
            m = run_scenario(name, out_dir, record=False, overrides=(overrides or []) + profile_overrides(profile))
            if profile != BASELINE_PROFILE:
                regress = []
            elif own:
                regress = relative_regressions(m, baseline.get(name), tolerance)
            else:
                regress = _regressions(m, baseline.get(name)) if label == "builtin" else []
            row = m.deterministic_dict() | {"profile": profile, "timing": m.timing, "regressions": regress}
            rows.append(row)
            ok &= m.passed and not regress
            bar.update()
            if interrupts.was_interrupted(m.reason):
                break
    for profile in profiles:
        gate = " (gated against the baseline)" if profile == BASELINE_PROFILE else ""
        print(f"stack: {label}, sensors profile: {profile}{gate}")
        print(
            "| scenario | distance (m) | max slip (%) | DR error (%) | VO error (%) | DR segments 1/5/10 m (%) "
            "| VO segments 1/5/10 m (%) | RMS DR / VO (m) | VO convergence (%) | pass | note |"
        )
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|:-:|---|")
        for r in (r for r in rows if r["profile"] == profile):
            good = r["passed"] and not r["regressions"]
            note = "; ".join(([] if r["passed"] else [r["reason"]]) + r["regressions"]) or r["reason"]
            seg, rms = r["kitti_segment_error_pct"], r["rms_position_error_m"]
            print(
                f"| {r['scenario']} | {_fmt(r['distance_m'])} | {_fmt(r['max_slip_pct'])} | "
                f"{_fmt(r['dr_error_pct'])} | {_fmt(r['vo_error_pct'])} | {_segments(seg.get('dead_reckoning'))} | "
                f"{_segments(seg.get('vo'))} | {_metres(rms.get('dead_reckoning'))} / {_metres(rms.get('vo'))} | "
                f"{_fmt(r['vo_convergence_pct'])} | {'yes' if good else 'NO'} | {note} |"
            )
    write_json(json_path, rows)
    complete = not any(interrupts.was_interrupted(r["reason"]) for r in rows)
    gated = [r for r in rows if r["profile"] == BASELINE_PROFILE]
    if update_baseline and (label == "builtin" or own) and complete and gated:
        keep = ("vo_error_pct", "vo_convergence_pct", "false_positives", "dr_error_pct", "max_slip_pct")
        merged = baseline | {r["scenario"]: {k: r[k] for k in keep} for r in gated}
        store.parent.mkdir(parents=True, exist_ok=True)
        store.write_text(json.dumps(merged, indent=2, sort_keys=True) + "\n")
    return rows, ok


def _committed() -> dict:
    return json.loads(BASELINE.read_text()) if BASELINE.is_file() else {}
