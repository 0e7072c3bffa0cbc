"""`rover-sim bench suite`: the scenario catalogue over seeds, its distribution verdicts and the regression gate.

Steps (:func:`bench_suite`):

1. the scenarios: the catalogue (sol-scale drives aside: ``bench traverse`` judges those) or, with ``fast``, the CI
   subset (``fast = true``); the seeds: ``--seeds`` (default: the first 8 of the published set, or with ``fast`` the
   first :data:`GATE_SEEDS` of the gate set); the profiles: flight and ideal (``fast``: the baseline's);
2. run every scenario x profile x seed (:mod:`rover_sim.bench.seeded`), the built-in stack and, beside it, each
   plugin stack (``--vo``/``--stereo``/``--planner``) on the same seeds;
3. judge each scenario over its seeds (:func:`rover_sim.runtime.acceptance.judge_distribution`) and, on the
   baseline's profile, against the baseline seed by seed (:mod:`rover_sim.bench.gate`);
4. print median [90 % CI] tables, the gate's table and the scorecard; write JSON, JUnit and a box-plot PNG.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from rover_sim.bench import gate, write_json
from rover_sim.bench.environment import environment
from rover_sim.bench.seeded import METRICS, Case, SeedRuns, cell, run_seeded
from rover_sim.bench.seeds import Seeds
from rover_sim.errors import ConfigError
from rover_sim.io.junit import Case as JunitCase
from rover_sim.resources import suite_baseline_path
from rover_sim.runtime import acceptance
from rover_sim.scenario.loading import catalogue, load_scenario

BASELINE_PROFILE = "flight"  # the profile the gate runs and the committed baseline was recorded on
PROFILES = ("flight", "ideal")
PUBLISHED_SEEDS = 8  # `bench suite` without --seeds: the first 8 of the published set
GATE_SEEDS = 16  # `bench suite --fast`: the first 16 of the gate set (see docs/benchmarks/statistics.md)
SPREAD_PERTURBATION = (1e-6, 1)  # --update-baseline's second run: 1 um and 1 urad, perturbation seed 1
TABLE_METRICS = ("distance_m", "max_slip_pct", "dr_error_pct", "vo_error_pct", "vo_convergence_pct", "goal_distance_m")
SCORECARD_METRIC = "vo_error_pct"  # the scorecard's summary: mean over VO scenarios of the median VO error


@dataclass
class StackResult:
    """One stack (built-in or a plugin set) over the scenarios, seeds and profiles."""

    label: str
    runs: list[SeedRuns]
    regression: dict[str, dict[str, gate.Regression]] = field(default_factory=dict)
    gated: bool = False
    replayed: bool = False  # an estimator replayed on another stack's inputs: reported, not in the exit status

    def scenario_passed(self, r: SeedRuns) -> tuple[bool, str]:
        """The scenario's verdict over its seeds: its distribution criteria, no gated metric regressed, every seed
        run (an interrupted run is reported as such)."""
        v = r.verdict()
        gated = self.regression.get(r.case.name, {}) if r.profile == BASELINE_PROFILE else {}
        problems = [f"regressed: {k}" for k, g in gated.items() if g.regressed]
        n_int = sum(e == "interrupted" for e in r.errors.values())
        if n_int:
            problems.insert(0, f"interrupted ({n_int} of {len(r.metrics)} seeds not run)")
        if not v.passed:
            problems.append(v.reason)
        return (not problems, "; ".join(problems) if problems else v.reason)

    @property
    def passed(self) -> bool:
        return all(self.scenario_passed(r)[0] for r in self.runs)


def scenario_names(fast: bool, only: tuple[str, ...] = ()) -> list[str]:
    """The suite's scenarios (sol-scale drives are `bench traverse`'s): the fast ones with ``fast``; ``only``: just
    these (each must be a catalogue scenario, else a ConfigError naming it)."""
    names = [n for n in catalogue() if (not fast or load_scenario(n).fast) and load_scenario(n).sol is None]
    unknown = [n for n in only if n not in names]
    if unknown:
        raise ConfigError("--scenario", unknown[0], f"not a suite scenario{' of --fast' if fast else ''}; choose from "
                          f"{', '.join(names)}")  # fmt: skip
    return [n for n in names if n in only] if only else names


def default_baseline(baseline_path: Path | None) -> Path:
    return Path(baseline_path) if baseline_path is not None else suite_baseline_path()


def replay_stacks(stack: StackResult) -> list[StackResult]:
    """The VOs replayed on ``stack``'s runs, each as a stack of its own (label: ``<impl> (replayed)``)."""
    labels = dict.fromkeys(label for r in stack.runs for label in r.replays)
    return [StackResult(f"{label} (replayed)", [r.replays[label] for r in stack.runs], replayed=True)
            for label in labels]  # fmt: skip


def run_stack(label: str, names: list[str], seeds: Seeds, profiles: tuple[str, ...], out_root: Path,
              overrides: list[str], **kw) -> StackResult:  # fmt: skip
    from tqdm import tqdm

    cases = [Case(n, n) for n in names]
    total = len(cases) * len(seeds) * len(profiles)
    with tqdm(total=total, desc=f"bench suite ({label})", unit="run", disable=None, leave=False) as bar:

        def progress(done: int, _total: int, what: str) -> None:
            bar.set_postfix_str(what)
            bar.update(done - bar.n)

        runs = run_seeded(cases, seeds.values, profiles, out_root / label.replace(":", "_"), overrides=overrides,
                          on_result=progress, **kw)  # fmt: skip
    return StackResult(label, runs)


def gated_values(runs: list[SeedRuns]) -> dict[str, dict[str, dict[int, float | None]]]:
    """scenario -> metric -> per seed, of the baseline profile's runs, for every gate metric."""
    keys = [m.key for m in acceptance.GATE.metrics]
    return {r.case.name: {k: r.values(k) for k in keys} for r in runs if r.profile == BASELINE_PROFILE}


def record_baseline(stack: StackResult, spread: StackResult, seeds: Seeds, path: Path) -> gate.Baseline:
    base = gate.Baseline(BASELINE_PROFILE, seeds.values, environment(),
                         {"size": SPREAD_PERTURBATION[0], "seed": SPREAD_PERTURBATION[1]},
                         gated_values(stack.runs), gated_values(spread.runs))  # fmt: skip
    gate.save_baseline(base, path)
    return base


# ------------------------------------------------------------------------------------------------- output


def print_tables(stack: StackResult, seeds: Seeds) -> None:
    for profile in dict.fromkeys(r.profile for r in stack.runs):
        print(f"\nstack: {stack.label}, sensors profile: {profile}, seeds: {_seed_text(seeds)} ({seeds.seed_set}); "
              "each cell: median [90 % bootstrap CI of the median]")  # fmt: skip
        head = " | ".join(METRICS[k].label for k in TABLE_METRICS)
        print(f"| scenario | pass rate | {head} | pass | reason |")
        print("|---|---:|" + "---:|" * len(TABLE_METRICS) + ":-:|---|")
        for r in (r for r in stack.runs if r.profile == profile):
            ok, why = stack.scenario_passed(r)
            s = r.summaries()
            cells = " | ".join(cell(s[k]) for k in TABLE_METRICS)
            print(f"| {r.case.name} | {r.verdict().pass_rate:.2f} | {cells} | {'yes' if ok else 'NO'} | {why} |")


def print_gate(stack: StackResult) -> None:
    if not stack.regression:
        return
    print(f"\nregression gate ({stack.label}, {BASELINE_PROFILE}): paired exact Wilcoxon signed-rank against the "
          f"baseline, Holm family-wise {acceptance.GATE.alpha:g}; min detectable: relative change found with "
          f"{100 * acceptance.GATE.power:g} % power at the strictest threshold, from the baseline's perturbed "
          "spread")  # fmt: skip
    print("| scenario | metric | pairs | median change | p | Holm threshold | min attainable p | min detectable | "
          "regressed |")  # fmt: skip
    print("|---|---|---:|---:|---:|---:|---:|---:|:-:|")
    for sc, per in stack.regression.items():
        for k, g in per.items():
            rel = "-" if g.delta_median_rel is None else f"{100 * g.delta_median_rel:+.1f} %"
            mdc = "-" if g.min_detectable_rel is None else f"{100 * g.min_detectable_rel:.1f} %"
            print(
                f"| {sc} | {k} | {g.n_pairs} | {g.delta_median:+.3g} ({rel}) | {g.p_value:.3g} | {g.threshold:.3g} | "
                f"{g.min_attainable_p:.2g} | {mdc} | {'YES' if g.regressed else 'no'} |"
            )


def _seed_text(seeds: Seeds) -> str:
    v = seeds.values
    contiguous = list(v) == list(range(v[0], v[0] + len(v)))
    return f"{v[0]}-{v[-1]}" if contiguous and len(v) > 2 else ",".join(map(str, v))


def stack_json(stack: StackResult) -> dict:
    out: dict = {}
    for r in stack.runs:
        ok, why = stack.scenario_passed(r)
        entry = {
            "pass_rate": r.verdict().pass_rate,
            "passed": ok,
            "reason": why,
            "criteria": acceptance.describe(r.scenario.passing),
            "cell_size_m": r.scenario.terrain.cell_size_m,
            "metrics": {k: s.as_json() for k, s in r.summaries().items()},
            "per_seed_verdicts": {str(s): {"passed": p, "reason": w} for s, (p, w) in r.run_verdicts().items()},
        }
        if r.profile == BASELINE_PROFILE and r.case.name in stack.regression:
            entry["regression"] = {k: g.as_json() for k, g in stack.regression[r.case.name].items()}
        out.setdefault(r.profile, {"scenarios": {}})["scenarios"][r.case.name] = entry
    return out


def scorecard(stacks: list[StackResult]) -> dict:
    """Per stack: the summary figure (mean over the VO scenarios of the median VO error, flight profile) and each
    scenario's median [CI] of the VO error, side by side."""
    vo_names = [r.case.name for r in stacks[0].runs
                if r.profile == BASELINE_PROFILE and r.summaries()[SCORECARD_METRIC].median is not None]  # fmt: skip
    out = {}
    for st in stacks:
        per = {r.case.name: r.summaries()[SCORECARD_METRIC] for r in st.runs if r.profile == BASELINE_PROFILE}
        medians = [per[n].median for n in vo_names if n in per and per[n].median is not None]
        out[st.label] = {
            "summary": round(sum(medians) / len(medians), 4) if len(medians) == len(vo_names) and medians else None,
            "summary_metric": f"mean over {len(vo_names)} VO scenarios of the median {SCORECARD_METRIC}",
            "scenarios": {n: per[n].as_json() for n in vo_names if n in per},
        }
    return out


def print_scorecard(card: dict) -> None:
    labels = list(card)
    names = list(next(iter(card.values()))["scenarios"])
    print(f"\nscorecard ({BASELINE_PROFILE}): VO error (%), median [90 % CI] per scenario")
    print("| scenario | " + " | ".join(labels) + " |")
    print("|---|" + "---:|" * len(labels))
    for n in names:
        cells = []
        for lab in labels:
            s = card[lab]["scenarios"].get(n)
            cells.append("-" if s is None or s["median"] is None else f"{s['median']:.2f} [{s['ci90'][0]:.2f}, "
                         f"{s['ci90'][1]:.2f}]")  # fmt: skip
        print(f"| {n} | " + " | ".join(cells) + " |")
    sums = " | ".join("-" if card[lab]["summary"] is None else f"**{card[lab]['summary']:.3f}**" for lab in labels)
    print(f"| summary: {next(iter(card.values()))['summary_metric']} | {sums} |")


def plot_scorecard(stacks: list[StackResult], path: Path) -> None:
    """Box plots of the per-seed VO error per scenario, one box per stack (flight profile)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [r.case.name for r in stacks[0].runs if r.profile == BASELINE_PROFILE
             and r.summaries()[SCORECARD_METRIC].median is not None]  # fmt: skip
    if not names:
        return
    fig, ax = plt.subplots(figsize=(max(6.0, 1.2 * len(names) * len(stacks)), 4.5))
    width = 0.8 / len(stacks)
    for i, st in enumerate(stacks):
        per = {r.case.name: r for r in st.runs if r.profile == BASELINE_PROFILE}
        data = [[v for v in per[n].values(SCORECARD_METRIC).values() if v is not None] if n in per else []
                for n in names]  # fmt: skip
        pos = [j + (i - (len(stacks) - 1) / 2) * width for j in range(len(names))]
        bp = ax.boxplot(data, positions=pos, widths=width * 0.9, patch_artist=True, manage_ticks=False)
        for box in bp["boxes"]:
            box.set_facecolor(f"C{i}")
            box.set_alpha(0.6)
        ax.plot([], [], color=f"C{i}", lw=6, alpha=0.6, label=st.label)
    ax.set_xticks(range(len(names)), names, rotation=30, ha="right")
    ax.set_ylabel("VO error (% of distance)")
    ax.set_title(f"bench suite: VO error per seed ({BASELINE_PROFILE} profile)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def junit_cases(stacks: list[StackResult]) -> list[JunitCase]:
    out = []
    for st in (s for s in stacks if not s.replayed):  # a replayed VO is reported in the JSON, not an exit status
        for r in st.runs:
            ok, why = st.scenario_passed(r)
            name = f"{r.case.name} ({r.profile})"
            cls = f"bench.suite.{st.label}"
            errors = [e for e in r.errors.values() if e != "interrupted"]
            if errors and len(errors) == len(r.errors) == len(r.metrics):
                out.append(JunitCase(name, cls, failure=why, error=errors[0]))
            else:
                out.append(JunitCase(name, cls, failure=None if ok else why))
    return out


# ------------------------------------------------------------------------------------------------- the bench


@dataclass
class SuiteResult:
    stacks: list[StackResult]
    data: dict

    @property
    def passed(self) -> bool:
        return self.data["passed"]


def bench_suite(
    json_path: str | None,
    seeds: Seeds,
    *,
    fast: bool = False,
    profiles: tuple[str, ...] | None = None,
    plugins: dict[str, list[str]] | None = None,
    replay: dict[str, str] | None = None,
    baseline_path: Path | None = None,
    update_baseline: bool = False,
    perturb: tuple[float, int] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    out_root: Path = Path("runs/bench_suite"),
    png_path: Path | None = None,
    only: tuple[str, ...] = (),
) -> SuiteResult:
    """See the module doc. ``plugins``: stack label -> ``--set`` overrides swapping the parts in (closed loop).
    ``replay``: label -> VO import path, run on the built-in stack's identical inputs (open loop, paired; reported
    and gated, not in the exit status). With ``fast`` or a ``baseline_path`` every stack is gated against the
    baseline (the committed one holds the built-in stack's figures: another VO must then be no worse than MER's);
    ``update_baseline`` writes the baseline from this run (the last stack's with your own ``baseline_path``) plus a
    perturbed run of the same stack (the spread the minimum detectable change is computed from). ``only``: run just
    these scenarios."""
    profiles = profiles or ((BASELINE_PROFILE,) if fast else PROFILES)
    names = scenario_names(fast, only)
    store = default_baseline(baseline_path)
    kw = {"perturb": perturb, "workers": workers, "scheduler": scheduler}
    baseline = None
    if not update_baseline and (fast or baseline_path is not None):
        baseline = gate.load_baseline(store)
        gate.check_power(len(seeds), gate.baseline_tests(baseline))
    stacks = [run_stack("builtin", names, seeds, profiles, out_root, [], **(kw | {"replay": replay}))]
    for label, sets in (plugins or {}).items():
        if interrupt_of(stacks) is None:
            stacks.append(run_stack(label, names, seeds, profiles, out_root, sets, **kw))
    stacks[1:1] = replay_stacks(stacks[0])
    if interrupt_of(stacks) is not None:
        update_baseline, baseline = False, None  # a cut-short run neither records nor gates
    if update_baseline:
        gated = stacks[-1] if baseline_path is not None else stacks[0]
        spread = run_stack(f"{gated.label}-perturbed", names, seeds, (BASELINE_PROFILE,), out_root,
                           (plugins or {}).get(gated.label, []), **(kw | {"perturb": SPREAD_PERTURBATION}))  # fmt: skip
        baseline = record_baseline(gated, spread, seeds, store)
    elif baseline is not None:  # every stack against the baseline: the built-in's own, or the reference for others
        for st in stacks:
            st.regression, st.gated = gate.compare(gated_values(st.runs), baseline, st.replayed), True
    report(stacks, seeds, png_path)
    data = suite_json(stacks, seeds, perturb, None if update_baseline else baseline, store)
    write_json(json_path, finite(data))
    return SuiteResult(stacks, data)


def report(stacks: list[StackResult], seeds: Seeds, png_path: Path | None) -> None:
    for st in stacks:
        print_tables(st, seeds)
        print_gate(st)
    if len(stacks) > 1:
        print_scorecard(scorecard(stacks))
        if png_path is not None:
            plot_scorecard(stacks, png_path)


def suite_json(stacks: list[StackResult], seeds: Seeds, perturb: tuple[float, int] | None,
               baseline: gate.Baseline | None, store: Path) -> dict:  # fmt: skip
    """The JSON: the built-in stack under ``profiles``, the others under ``plugins`` (closed loop) and
    ``replayed`` (open loop on the built-in stack's inputs), the scorecard; ``passed`` from the closed-loop stacks."""
    return {
        "seeds": list(seeds.values),
        "seed_set": seeds.seed_set,
        "perturb": None if perturb is None else perturb[0],
        "perturb_seed": None if perturb is None else perturb[1],
        "environment": environment(),
        "baseline": None
        if baseline is None
        else {"path": str(store), "environment": baseline.environment, "seeds": list(baseline.seeds)},  # fmt: skip
        "passed": all(st.passed for st in stacks if not st.replayed),
        "profiles": stack_json(stacks[0]),
        "plugins": {st.label: {"profiles": stack_json(st)} for st in stacks[1:] if not st.replayed},
        "replayed": {st.label: {"profiles": stack_json(st), "passed": st.passed} for st in stacks if st.replayed},
        "scorecard": scorecard(stacks) if len(stacks) > 1 else {},
    }


def interrupt_of(stacks: list[StackResult]) -> KeyboardInterrupt | None:
    """The Ctrl-C / SIGTERM that cut a stack's runs short, if any."""
    return next((r.interrupt for st in stacks for r in st.runs if r.interrupt is not None), None)


def finite(obj):  # noqa: ANN001, ANN202
    """NaN/inf -> None, so the JSON is strict."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite(v) for v in obj]
    return obj
