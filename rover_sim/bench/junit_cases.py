"""Each benchmark's result as JUnit test cases (``--junit PATH``), built from the verdicts of
:mod:`rover_sim.runtime.acceptance` (the judge the console tables, the JSON and the exit status use too): one case
per check, row, case, plugin or field; a failure's message is the unmet bar with the measured value. Written by
:mod:`rover_sim.io.junit`."""

from __future__ import annotations

from rover_sim.io.junit import Case, case
from rover_sim.runtime.acceptance import Verdict, bars


def verdict_cases(v: Verdict, classname: str) -> list[Case]:
    """One case per check (failure: why it failed); an error case when the benchmark did not complete."""
    out = [case(c.name, classname, c.passed, c.why or c.name) for c in v.checks]
    if v.error is not None:
        out.append(Case("run", classname, failure=v.error, error=v.error))
    return out


def slip_cases(result: dict) -> list[Case]:
    return verdict_cases(bars.slip_verdict(result), "bench.slip")


def mobility_cases(result: dict) -> list[Case]:
    """`bench slip --soil-model wong_reece`: one case per slip row and per mobility check (the Wong–Reece law)."""
    return verdict_cases(bars.mobility_verdict(result), "bench.slip.wong_reece")


def autonav_cases(result: dict) -> list[Case]:
    """One case per field (reached within the bar's distance, no collision) and one for the summary bar."""
    cls = f"bench.autonav.{result.get('stack', 'builtin')}"
    out = []
    for r in result["rows"]:
        v = bars.autonav_field_verdict(r)
        out.append(Case(f"field {r['seed']:02d}", cls, failure=None if v.passed else v.reason, error=v.error))
    v = bars.autonav_verdict(result)
    return out + [case("summary", cls, v.passed, v.reason)]


def render_cases(result: dict) -> list[Case]:
    return verdict_cases(bars.render_verdict(result), "bench.render")


def stereo_cases(result: dict) -> list[Case]:
    return verdict_cases(bars.stereo_verdict(result), "bench.stereo")


def dimes_cases(result: dict) -> list[Case]:
    return verdict_cases(bars.dimes_verdict(result), "bench.dimes")


def sweep_cases(result: dict) -> list[Case]:
    return verdict_cases(bars.sweep_verdict(result), "bench.sweep")


def rocks_cases(result: dict) -> list[Case]:
    return verdict_cases(bars.rocks_verdict(result), "bench.rocks")


def traverse_cases(result: dict) -> list[Case]:
    """`bench traverse`: one case per drive, failing with its unmet bars."""
    out = []
    for r in result["details"]:
        v = bars.traverse_verdict(r)
        out.append(case(r["name"], "bench.traverse", v.passed, v.reason))
    return out
