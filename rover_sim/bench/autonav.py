"""`rover-sim bench autonav`: GESTALT autonomous navigation over seeded rock fields and their acceptance bars.

20 seeded fields, rocks up to 60 cm at 10 % cover (Golombek-Rapp k = 0.10), goal 20 m away. Counts runs whose
final true position is within 1 m of the goal, runs with any ground-truth contact of the body (or of any part
with a rock at least 25 cm tall), and the GESTALT cycle time (stereo + map + votes).

The rover's own pose drives everything (never the truth): wheel/IMU dead reckoning corrected by navcam visual
odometry after every step, as MER drove autonav with VO on. Dead reckoning alone is 4-5 % of distance on these
fields (sand patches slip 5-10 %), which on a 20-40 m detour is most of the 1 m budget; the hazcams, which GESTALT
uses, look too steeply at too little texture for VO (most steps find too few features).
"""

from __future__ import annotations

import numpy as np

from rover_sim import interrupts
from rover_sim.bench import write_json
from rover_sim.runtime.acceptance import bars
from rover_sim.runtime.run import run_scenario
from rover_sim.scenario.loading import scenario_from_dict

GOAL_DISTANCE_M = 20.0
REACH_M = bars.AUTONAV.reach_m  # the bar: rover_sim.runtime.acceptance


def field_scenario(seed: int, cover: float = 0.10, max_height_m: float = 0.6) -> dict:
    x0, x1 = -GOAL_DISTANCE_M / 2, GOAL_DISTANCE_M / 2
    return {
        "name": f"autonav_field_{seed:02d}",
        "seed": seed,
        "terrain": {
            "size_m": [GOAL_DISTANCE_M + 8, 16],
            "cell_size_m": 0.05,
            "roughness": {"rms_m": 0.015, "correlation_length_m": 1.5},
            "rocks": {
                "cover_fraction": cover,
                "min_height_m": 0.08,
                "max_height_m": max_height_m,
                "exclusion_zones": [[x0, 0, 1.5], [x1, 0, 1.2]],
            },
            "material": {"kind": "patches", "bedrock_fraction": 0.2, "mixed_fraction": 0.3, "patch_scale_m": 3.0},
        },
        "start": {"x_m": x0, "y_m": 0, "yaw_deg": 0},
        # GESTALT ranges with the front hazcams (mission.autonav); VO, which keeps the onboard pose honest on the
        # sandy patches (5-10 % slip), uses the navcams as on MER
        "nav": {"vo": True, "camera": "navcam", "image_noise": True},
        "commands": [{"type": "autonav", "x_m": x1, "y_m": 0, "tolerance_m": 0.6, "max_cycles": 150}],
        "pass": {"goal_within_m": REACH_M, "max_body_collisions": 0},
    }


def run_field(seed: int, overrides: tuple[str, ...] = ()) -> dict:
    """One seeded field, run to the end; the row the table prints (top level: a spawn-pool worker calls it).
    ``overrides``: ``--set``-style overrides (e.g. a plugin planner or stereo matcher)."""
    sc = scenario_from_dict(field_scenario(seed), source=f"autonav field {seed}", overrides=list(overrides))
    m = run_scenario(sc, None, record=False)
    a = m.extra.get("autonav", {})
    return {
        "seed": seed,
        "reached": m.goal_distance_m is not None and m.goal_distance_m <= REACH_M,
        "goal_distance_m": m.goal_distance_m,
        "collision": m.body_collisions > 0 or m.tall_rock_contacts > 0,
        "body_collisions": m.body_collisions,
        "tall_rock_contacts": m.tall_rock_contacts,
        "cycles": a.get("cycles"),
        "cycle_ms_median": m.timing.get("autonav_cycle_ms_median"),
        "outcome": a.get("outcome"),
        "distance_m": m.distance_m,
        "reason": m.reason,
        # the field did not run to its end (physics diverged, a plugin raised; or Ctrl-C / SIGTERM)
        "error": m.reason if m.reason.startswith("run did not complete") else None,
    }


def _row_line(r: dict) -> str:
    goal = "-" if r["goal_distance_m"] is None else f"{r['goal_distance_m']:.2f}"
    line = (
        f"seed {r['seed']:2d}: {'reached' if r['reached'] else 'MISSED '} {goal} m from goal, "
        f"{'COLLISION' if r['collision'] else 'no collision'}, {r['cycles']} cycles, {r['distance_m']:.1f} m "
        f"driven, {r['outcome']}"
    )
    return f"{line} ({r['error']})" if r.get("error") else line


def _rows(seeds: list[int], workers: int, overrides: tuple[str, ...] = ()):
    """Rows in completion order: in this process (``workers <= 1``) or on a ``spawn`` pool (never fork: the
    renderer holds a GL context)."""
    if workers <= 1:
        for seed in seeds:
            yield run_field(seed, overrides)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    from rover_sim.apps.sweep import init_worker

    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=min(workers, len(seeds)), mp_context=ctx, initializer=init_worker) as pool:
        for fut in as_completed([pool.submit(run_field, s, overrides) for s in seeds]):
            yield fut.result()


def bench_autonav(
    json_path: str | None = None,
    runs: int = 20,
    first_seed: int = 0,
    workers: int = 1,
    seeds: list[int] | None = None,
    overrides: tuple[str, ...] = (),
    label: str = "builtin",
) -> dict:
    """Run the fields (``seeds``, default ``first_seed .. first_seed + runs - 1``), print one line per field and the
    summary table; with ``workers > 1`` the fields run on a spawn pool (cycle times are then measured with the cores
    shared, so quote them from a ``workers = 1`` run)."""
    seeds = list(seeds) if seeds else list(range(first_seed, first_seed + runs))
    from tqdm import tqdm

    rows = []
    print(f"stack: {label}", flush=True)
    with tqdm(total=len(seeds), desc=f"bench autonav ({label})", unit="field", disable=None, leave=False) as bar:
        for r in _rows(seeds, workers, tuple(overrides)):
            rows.append(r)
            bar.write(_row_line(r))
            bar.update()
            if interrupts.was_interrupted(r["reason"]):
                break  # Ctrl-C / SIGTERM: the summary covers the fields that ran (the CLI exits 130 / 143)
    rows.sort(key=lambda r: r["seed"])
    ms = [r["cycle_ms_median"] for r in rows if r["cycle_ms_median"] is not None]
    result = {
        "runs": len(rows),
        "reached": sum(r["reached"] for r in rows),
        "collisions": sum(r["collision"] for r in rows),
        "cycle_ms_median": float(np.median(ms)) if ms else None,
        "stack": label,
        "rows": rows,
    }
    bar = bars.AUTONAV
    verdict = bars.autonav_verdict(result)  # the one judge: this table, the JSON, the JUnit, the exit status
    result["passed"], result["reasons"] = verdict.passed, verdict.reasons
    ms_text = "-" if result["cycle_ms_median"] is None else f"{result['cycle_ms_median']:.1f}"
    print()
    print(
        f"| runs | reached within {bar.reach_m:g} m | collisions (body, or rock >= 25 cm) | GESTALT cycle ms (median) "
        "| acceptance | pass |"
    )
    print("|---:|---:|---:|---:|---|---|")
    print(
        f"| {result['runs']} | {result['reached']} ({100 * result['reached'] / max(1, len(rows)):.0f} %) | "
        f"{result['collisions']} | {ms_text} | >= {100 * bar.min_reached_frac:.0f} % reached, "
        f"{bar.max_collisions} collisions, <= {bar.max_cycle_ms:.0f} ms | {verdict.cell()} |"
    )
    write_json(json_path, result)
    return result
