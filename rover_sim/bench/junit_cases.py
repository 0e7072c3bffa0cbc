"""Each benchmark's result as JUnit test cases (``--junit PATH``), built from the verdicts of
:mod:`rover_sim.mission.acceptance` (the judge the console tables, the JSON and the exit status use too): one case
per check, row, case, plugin or field; a failure's message is the unmet bar with the measured value. Written by
:mod:`rover_sim.io.junit`."""

from __future__ import annotations

from rover_sim.io.junit import Case, case, scenario_case
from rover_sim.mission import acceptance
from rover_sim.mission.acceptance import Verdict


def verdict_cases(v: Verdict, classname: str) -> list[Case]:
    """One case per check (failure: why it failed); an error case when the benchmark did not complete."""
    out = [case(c.name, classname, c.passed, c.why or c.name) for c in v.checks]
    if v.error is not None:
        out.append(Case("run", classname, failure=v.error, error=v.error))
    return out


def slip_cases(result: dict) -> list[Case]:
    return verdict_cases(acceptance.slip_verdict(result), "bench.slip")


def mobility_cases(result: dict) -> list[Case]:
    """`bench slip --soil-model wong_reece`: one case per slip row and per mobility check (the Wong–Reece law)."""
    return verdict_cases(acceptance.mobility_verdict(result), "bench.slip.wong_reece")


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
    """One case per field (reached within the bar's distance, no collision) and one for the summary bar."""
    cls = f"bench.autonav.{result.get('stack', 'builtin')}"
    out = []
    for r in result["rows"]:
        v = acceptance.autonav_field_verdict(r)
        out.append(Case(f"field {r['seed']:02d}", cls, failure=None if v.passed else v.reason, error=v.error))
    v = acceptance.autonav_verdict(result)
    return out + [case("summary", cls, v.passed, v.reason)]


def render_cases(result: dict) -> list[Case]:
    return verdict_cases(acceptance.render_verdict(result), "bench.render")


def stereo_cases(result: dict) -> list[Case]:
    return verdict_cases(acceptance.stereo_verdict(result), "bench.stereo")


def dimes_cases(result: dict) -> list[Case]:
    return verdict_cases(acceptance.dimes_verdict(result), "bench.dimes")


def sweep_cases(result: dict) -> list[Case]:
    return verdict_cases(acceptance.sweep_verdict(result), "bench.sweep")


def rocks_cases(result: dict) -> list[Case]:
    return verdict_cases(acceptance.rocks_verdict(result), "bench.rocks")


def traverse_cases(result: dict) -> list[Case]:
    """`bench traverse`: one case per drive, failing with its unmet bars."""
    out = []
    for r in result["details"]:
        v = acceptance.traverse_verdict(r)
        out.append(case(r["name"], "bench.traverse", v.passed, v.reason))
    return out
