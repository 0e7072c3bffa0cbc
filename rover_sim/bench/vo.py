"""`rover-sim bench vo`: the VO cases over seeds, MER VO beside the ideal profile, the full-pose update and plugins.

Each case is a catalogue scenario run closed loop (physics, rendering, sensors, the nav stack), on every seed of
``--seeds`` (default: the first 8 of the published set). Per case and variant: each figure's median [90 % CI],
the scenario's verdict over the seeds (its per-run criteria, its pass rate and distribution bounds, judged by
:mod:`rover_sim.runtime.acceptance`), and VO's covariance consistency (NEES). The variants: MER VO on the flight
profile (judged), and unless ``quick`` on the ideal profile and with the full-pose update (reported), plus each
``--vo`` plugin on the flight profile (judged), all on the same seeds.
"""

from __future__ import annotations

from pathlib import Path

from rover_sim.bench import write_json
from rover_sim.bench.environment import environment
from rover_sim.bench.seeded import Case, SeedRuns, cell, run_seeded
from rover_sim.bench.seeds import Seeds
from rover_sim.bench.suite import StackResult, finite, interrupt_of, print_tables, scorecard, stack_json
from rover_sim.io.junit import Case as JunitCase
from rover_sim.scenario.loading import plugin_overrides
from rover_sim.scenario.schema import Scenario

VO_CASES: dict[str, str] = {
    "msstb": "msstb_rock_course",
    "slope30m": "slope30m",
    "featureless": "meridiani_plains",
    "shadow": "sol235_shadow",
    "flat": "flat_benign",
}
BUILTIN = "MER VO"
FULL_POSE = "MER VO, full-pose update"


def _stack(label: str, cases: list[Case], seeds: Seeds, profiles: tuple[str, ...], out_root: Path,
           overrides: list[str], **kw) -> StackResult:  # fmt: skip
    from tqdm import tqdm

    with tqdm(total=len(cases) * len(seeds) * len(profiles), desc=f"bench vo ({label})", unit="run", disable=None,
              leave=False) as bar:  # fmt: skip

        def progress(done: int, _total: int, what: str) -> None:
            bar.set_postfix_str(what)
            bar.update(done - bar.n)

        runs = run_seeded(cases, seeds.values, profiles, out_root / label.replace(":", "_").replace(" ", "_"),
                          overrides=overrides, on_result=progress, **kw)  # fmt: skip
    return StackResult(label, runs)


def print_nees(stack: StackResult) -> None:
    """VO's covariance consistency per case: medians over seeds of the per-run NEES medians (per accepted step and
    over 5 m of consecutive steps; a consistent covariance gives about 2.37, 3 dof)."""
    print(f"\n| {stack.label} | case | profile | NEES per step | NEES over 5 m |")
    print("|---|---|---|---:|---:|")
    for r in stack.runs:
        s = r.summaries()
        print(f"| | {r.case.name} | {r.profile} | {cell(s['vo_nees_step'])} | {cell(s['vo_nees_5m'])} |")


def bench_vo(
    json_path: str | None,
    seeds: Seeds,
    *,
    plugins: list[str] | None = None,
    cases: list[str] | None = None,
    case_scenarios: dict[str, str | Path | Scenario] | None = None,
    quick: bool = False,
    perturb: tuple[float, int] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    out_root: Path = Path("runs/bench_vo"),
) -> tuple[list[StackResult], dict]:
    """See the module doc. ``case_scenarios`` replaces the case list (case name -> scenario name, path or object).
    Returns the stacks and the JSON written: the same layout as ``bench suite --json`` with the VO cases as its
    scenarios; the full-pose update and the plugins under ``"plugins"``."""
    all_cases = case_scenarios if case_scenarios is not None else VO_CASES
    chosen = [Case(c, s) for c, s in all_cases.items() if cases is None or c in cases]
    kw = {"perturb": perturb, "workers": workers, "scheduler": scheduler}
    stacks = [_stack(BUILTIN, chosen, seeds, ("flight",) if quick else ("flight", "ideal"), out_root, [], **kw)]
    variants = [] if quick else [(FULL_POSE, ['nav.vo.update="full_pose"'])]
    variants += [(p, plugin_overrides(vo=p)) for p in plugins or []]
    for label, sets in variants:
        if interrupt_of(stacks) is None:
            stacks.append(_stack(label, chosen, seeds, ("flight",), out_root, sets, **kw))
    for st in stacks:
        print_tables(st, seeds)
        print_nees(st)
    judged = [st for st in stacks if st.label != FULL_POSE]
    data = {
        "seeds": list(seeds.values),
        "seed_set": seeds.seed_set,
        "perturb": None if perturb is None else perturb[0],
        "perturb_seed": None if perturb is None else perturb[1],
        "environment": environment(),
        "passed": all(_flight_passed(st) for st in judged),
        "profiles": stack_json(stacks[0]),
        "plugins": {st.label: {"profiles": stack_json(st)} for st in stacks[1:]},
        "scorecard": scorecard(stacks) if len(stacks) > 1 else {},
    }
    write_json(json_path, finite(data))
    return stacks, data


def _flight_passed(stack: StackResult) -> bool:
    """A variant's verdict: every case on the flight profile (the ideal profile is reported beside, not judged)."""
    return all(stack.scenario_passed(r)[0] for r in stack.runs if r.profile == "flight")


def junit_cases(stacks: list[StackResult]) -> list[JunitCase]:
    """One case per VO case for MER VO (flight profile) and per case for each plugin; the ideal profile and the
    full-pose update are reported, not judged."""
    out = []
    for st in stacks:
        if st.label == FULL_POSE:
            continue
        for r in (r for r in st.runs if r.profile == "flight"):
            ok, why = st.scenario_passed(r)
            out.append(JunitCase(r.case.name, f"bench.vo.{st.label}", failure=None if ok else why))
    return out


def runs_of(stacks: list[StackResult], label: str, profile: str = "flight") -> dict[str, SeedRuns]:
    """case -> runs of one variant and profile."""
    st = next(s for s in stacks if s.label == label)
    return {r.case.name: r for r in st.runs if r.profile == profile}
