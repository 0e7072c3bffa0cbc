"""Each benchmark's result as JUnit test cases (``--junit PATH``): one case per row, case, plugin, field or bar;
a failure's message is the unmet criterion with the measured value. Written by :mod:`rover_sim.io.junit`."""

from __future__ import annotations

from rover_sim.io.junit import Case, case, scenario_case
from rover_sim.mission import acceptance


def slip_cases(result: dict) -> list[Case]:
    from rover_sim.bench.slip import SlipRow, anchor, passes

    out = []
    for r in result["rows"]:
        row = SlipRow(**r)
        name = f"{row.material} {row.slope_deg:g} deg"
        out.append(
            case(name, "bench.slip", passes(row), f"slip {100 * row.slip:.1f} %: {anchor(row.material, row.slope_deg)}")
        )
    drift, rtf, ratio = result["parked_30deg_bedrock_drift_m"], result["realtime_factor"], result["bare_mujoco_ratio"]
    out += [
        case(
            "sand slip monotonic in slope", "bench.slip", result["sand_monotonic"], "sand slip not monotonic in slope"
        ),
        case("parked 30 deg bedrock drift", "bench.slip", drift < 0.01, f"drift {100 * drift:.2f} cm >= 1 cm in 60 s"),
        case("real-time factor", "bench.slip", rtf >= 20, f"real-time factor {rtf:.0f}x < 20x"),
        case("ratio to bare MuJoCo", "bench.slip", ratio >= 0.3, f"ratio to bare MuJoCo {ratio:.2f} < 0.3"),
    ]
    return out


def mobility_cases(result: dict) -> list[Case]:
    """`bench slip --soil-model wong_reece`: one case per slip row and per mobility check (the Wong–Reece law)."""
    from rover_sim.bench.slip import SlipRow, anchor, passes

    out = []
    for r in result["rows"]:
        row = SlipRow(**r)
        msg = f"slip {100 * row.slip:.1f} %: {anchor(row.material, row.slope_deg)}"
        out.append(case(f"{row.material} {row.slope_deg:g} deg", "bench.slip.wong_reece", passes(row), msg))
    for c in result["checks"]:
        msg = f"{c['measured']} (acceptance {c['acceptance']})"
        out.append(case(c["name"], "bench.slip.wong_reece", c["ok"], msg))
    return out


def wheel_cases(result: dict) -> list[Case]:
    """`bench wheel`: one case per wheel, band and quantity, one per wheel's 0 deg monotonicity; a failure's
    message is the verdict's reason (rover_sim.mission.acceptance.judge_wheel)."""
    out = []
    for name, w in result["wheels"].items():
        for band in acceptance.WHEEL.bands:
            for q in acceptance.WHEEL_QUANTITIES:
                v = w["rmse_by_band"][band.key][q]
                if v is not None:
                    why = next((r for r in result["reasons"] if r.startswith(f"{name} {band.key} deg: {q} ")), "")
                    out.append(case(f"{name} {band.key} deg {q}", "bench.wheel", not why, why))
        if any(r["wheel"] == name and r["slip_angle_deg"] == 0.0 for r in result["rows"]):
            why = next((r for r in result["reasons"] if r.startswith(f"{name} 0 deg: drawbar")), "")
            out.append(case(f"{name} 0 deg drawbar pull non-decreasing in slip", "bench.wheel", not why, why))
    if not out:
        out.append(case("bench wheel", "bench.wheel", result["passed"], "; ".join(result["reasons"])))
    return out


def vo_cases(results: dict) -> list[Case]:
    """One case per VO case for MER VO (flight profile), and per case for each plugin (``bench.vo.<plugin>``);
    the ideal-profile and full-pose comparison runs are reported, not judged."""
    from rover_sim.bench.missions import COMPARISON_KEYS

    out = [
        scenario_case(r, "bench.vo.builtin", name) for name, r in results.items() if name not in COMPARISON_KEYS
    ]
    for plugin, per in results.get("plugins", {}).items():
        out += [scenario_case(r, f"bench.vo.{plugin}", case_name) for case_name, r in per.items()]
    return out


def suite_cases(rows: list[dict], label: str = "builtin") -> list[Case]:
    """One case per scenario; a regression past the baseline is a failure too."""
    out = []
    for r in rows:
        c = scenario_case(r, f"bench.suite.{label}")
        if r.get("regressions") and c.failure is None:
            c = Case(c.name, c.classname, failure="; ".join(r["regressions"]), time_s=c.time_s)
        out.append(c)
    return out


def autonav_cases(result: dict) -> list[Case]:
    """One case per field (reached within 1 m, no collision) and one for the summary bar."""
    cls = f"bench.autonav.{result.get('stack', 'builtin')}"
    out = []
    for r in result["rows"]:
        why = []
        if r.get("error"):
            out.append(Case(f"field {r['seed']:02d}", cls, failure=r["error"], error=r["error"]))
            continue
        if not r["reached"]:
            why.append(f"ended {r['goal_distance_m']} m from the goal (> 1 m)")
        if r["collision"]:
            why.append(f"{r['body_collisions']} body-collision ticks, {r['tall_rock_contacts']} tall-rock ticks")
        out.append(case(f"field {r['seed']:02d}", cls, not why, "; ".join(why)))
    bar = acceptance.AUTONAV
    ms = result["cycle_ms_median"]
    why = []
    if result["reached"] < bar.min_reached_frac * result["runs"]:
        why.append(f"{result['reached']}/{result['runs']} reached (< {100 * bar.min_reached_frac:.0f} %)")
    if result["collisions"] > bar.max_collisions:
        why.append(f"{result['collisions']} fields with collisions (> {bar.max_collisions})")
    if ms is not None and ms > bar.max_cycle_ms:
        why.append(f"GESTALT cycle {ms:.1f} ms (> {bar.max_cycle_ms:g} ms)")
    out.append(case("summary", cls, not why, "; ".join(why)))
    return out


def render_cases(result: dict) -> list[Case]:
    ms, bar = result["stereo_pair_256_shadows_ms"], acceptance.RENDER.max_pair_256_shadows_ms
    return [case("256x256 stereo pair with shadows", "bench.render", ms <= bar, f"{ms:.1f} ms > {bar:g} ms")]


def stereo_cases(result: dict) -> list[Case]:
    bar = acceptance.STEREO.max_time_ratio
    out = [
        case("speed vs StereoBM", "bench.stereo", result["ratio"] <= bar, f"ratio {result['ratio']:.2f} > {bar:g}"),
        case(
            "bad-1px vs StereoBM",
            "bench.stereo",
            result["ours_bad1"] < result["stereobm_bad1"],
            f"bad-1px {100 * result['ours_bad1']:.2f} % >= StereoBM {100 * result['stereobm_bad1']:.2f} %",
        ),  # fmt: skip
    ]
    for key in sorted(k for k in result if k.startswith("ratio_")):
        res, ratio = key.removeprefix("ratio_"), result[key]
        out.append(case(f"speed vs StereoBM @{res} px", "bench.stereo", ratio <= bar, f"ratio {ratio:.2f} > {bar:g}"))
    return out


def dimes_cases(result: dict) -> list[Case]:
    sigma, bar = result["velocity_error_1sigma_mps"], acceptance.DIMES
    ok_sigma = sigma is not None and sigma <= bar.max_velocity_error_1sigma_m_s and result["runs"] >= bar.min_runs
    return [
        case(
            "horizontal velocity error 1-sigma",
            "bench.dimes",
            ok_sigma,
            f"{sigma} m/s over {result['runs']} descents (need <= {bar.max_velocity_error_1sigma_m_s} m/s over "
            f">= {bar.min_runs})",
        ),  # fmt: skip
        case(
            "featureless plain rejected",
            "bench.dimes",
            result["featureless_rejected"],
            "an estimate was accepted over the featureless plain",
        ),  # fmt: skip
    ]


def sweep_cases(result: dict) -> list[Case]:
    bar = acceptance.SWEEP.max_parallel_ratio
    return [case("2-worker speed-up", "bench.sweep", result["passed"], f"parallel/serial {result['ratio']} > {bar}")]


def rocks_cases(result: dict) -> list[Case]:
    b = acceptance.ROCKS
    checks = [
        ("extraction recall", result["recall"] >= b.recall, f"recall {result['recall']:.3f} < {b.recall}"),
        (
            "extraction precision",
            result["precision"] >= b.precision,
            f"precision {result['precision']:.3f} < {b.precision}",
        ),  # fmt: skip
        (
            "model RMS",
            result["median_rms_m"] <= b.median_rms_m,
            f"median RMS {result['median_rms_m']:.3f} m > {b.median_rms_m} m",
        ),  # fmt: skip
        (
            "correct matches",
            result["match_correct_frac"] >= b.match_correct_frac,
            f"{result['match_correct_frac']:.3f} < {b.match_correct_frac}",
        ),  # fmt: skip
        (
            "site-to-site error",
            result["site_error_pct"] <= b.site_error_pct,
            f"{result['site_error_pct']:.2f} % > {b.site_error_pct} %",
        ),  # fmt: skip
        (
            "model type, well observed",
            result["model_type_match_frac_well_observed"] >= b.model_type_match_frac_well_observed,
            f"{result['model_type_match_frac_well_observed']:.2f} < {b.model_type_match_frac_well_observed}",
        ),  # fmt: skip
    ]
    c = result["chain_error_m"]
    checks.append(("chain adjustment beats DR and VO", c["adjusted"] < min(c["dead_reckoning"], c["vo"]),
                   f"adjusted {c['adjusted']:.3f} m, DR {c['dead_reckoning']:.3f} m, VO {c['vo']:.3f} m"))  # fmt: skip
    return [case(name, "bench.rocks", ok, msg) for name, ok, msg in checks]


def traverse_cases(result: dict) -> list[Case]:
    """`bench traverse`: one case per drive, failing with the unmet issue-18 bars."""
    return [case(r["name"], "bench.traverse", r["passed"], r["why"]) for r in result["details"]]
