"""Benchmark tables from a benchmark's committed JSON (``bench suite --json`` / ``bench vo --json``), for the docs.

Every table states what it was measured on: the seeds and their set, the sensor profile, each scenario's terrain
cell size, the perturbation if any, and the machine (CPU, package versions, commit) from the JSON's
``environment``. ``rover-sim bench report JSON`` prints the markdown; the docs build calls :func:`markdown`.
"""

from __future__ import annotations

import json
from pathlib import Path

from rover_sim.bench.seeded import METRICS

COLUMNS = ("distance_m", "max_slip_pct", "dr_error_pct", "vo_error_pct", "vo_convergence_pct", "goal_distance_m")


def _cell(m: dict | None, digits: int = 2) -> str:
    if not m or m.get("median") is None:
        return "-"
    lo, hi = m["ci90"]
    return f"{m['median']:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def _seeds(data: dict) -> str:
    v = data["seeds"]
    text = f"{v[0]}–{v[-1]}" if v == list(range(v[0], v[0] + len(v))) and len(v) > 2 else ", ".join(map(str, v))
    return f"{len(v)} seeds ({text}, {data['seed_set']} set)"


def machine(data: dict) -> str:
    env = data.get("environment") or {}
    pk = env.get("packages") or {}
    parts = [f"{env.get('cpu', '?')} ({env.get('cpus', '?')} CPUs)", f"Python {env.get('python', '?')}"]
    parts += [f"{k} {pk[k]}" for k in ("mujoco", "numpy", "opencv-python-headless", "numba") if pk.get(k)]
    if env.get("commit"):
        parts.append(f"commit {env['commit']}")
    return ", ".join(parts)


def profile_table(scenarios: dict) -> list[str]:
    head = " | ".join(METRICS[k].label for k in COLUMNS)
    lines = [f"| scenario | cell (m) | pass rate | {head} | holds | criteria |",
             "|---|---:|---:|" + "---:|" * len(COLUMNS) + ":-:|---|"]  # fmt: skip
    for name, sc in scenarios.items():
        cells = " | ".join(_cell(sc["metrics"].get(k)) for k in COLUMNS)
        verdict = "yes" if sc["passed"] else f"NO: {sc['reason']}"
        lines.append(f"| {name} | {sc.get('cell_size_m', '-')} | {sc['pass_rate']:.2f} | {cells} | {verdict} | "
                     f"{sc.get('criteria', '')} |")  # fmt: skip
    return lines


def markdown(data: dict, title: str = "") -> str:
    """Markdown of a ``bench suite`` or ``bench vo`` JSON: one table per stack and profile (median [90 % CI] of
    each figure over the seeds), with what it was measured on."""
    out = [f"### {title}", ""] if title else []
    pert = "" if data.get("perturb") is None else f", perturbed {data['perturb']:g}:{data.get('perturb_seed')}"
    out += [f"{_seeds(data)}{pert}. Machine: {machine(data)}. Each cell: median [90 % bootstrap CI of the median] "
            "over the seeds.", ""]  # fmt: skip
    stacks = [("built-in stack", data["profiles"])]
    stacks += [(label, s["profiles"]) for label, s in (data.get("plugins") or {}).items()]
    for label, profiles in stacks:
        for profile, block in profiles.items():
            out += [f"**{label}, {profile} profile**", "", *profile_table(block["scenarios"]), ""]
    return "\n".join(out)


def main(path: str) -> str:
    return markdown(json.loads(Path(path).read_text()))
