"""`rover-sim bench autonav`: GESTALT autonomous navigation over seeded rock fields (issue acceptance).

20 seeded fields, rocks up to 60 cm at 10 % cover (Golombek-Rapp k = 0.10), goal 20 m away. Counts runs whose
final true position is within 1 m of the goal, runs with any ground-truth contact of the body (or of any part
with a rock at least 25 cm tall), and the GESTALT cycle time (stereo + map + votes).
"""

from __future__ import annotations

import numpy as np

from rover_sim.bench import write_json
from rover_sim.runner import run_scenario
from rover_sim.scenario import scenario_from_dict

GOAL_DISTANCE_M = 20.0
REACH_M = 1.0


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
        "nav": {"vo": False, "camera": "hazcam_front", "image_noise": True},
        "commands": [{"type": "autonav", "x_m": x1, "y_m": 0, "tolerance_m": 0.6, "max_cycles": 150}],
        "pass": {"goal_within_m": REACH_M, "max_body_collisions": 0},
    }


def bench_autonav(json_path: str | None = None, runs: int = 20, first_seed: int = 0) -> dict:
    rows = []
    for seed in range(first_seed, first_seed + runs):
        sc = scenario_from_dict(field_scenario(seed), source=f"autonav field {seed}")
        m = run_scenario(sc, None, record=False)
        a = m.extra.get("autonav", {})
        rows.append(
            {
                "seed": seed,
                "reached": m.goal_distance_m is not None and m.goal_distance_m <= REACH_M,
                "goal_distance_m": m.goal_distance_m,
                "collision": m.body_collisions > 0 or m.tall_rock_contacts > 0,
                "cycles": a.get("cycles"),
                "cycle_ms_median": m.timing.get("autonav_cycle_ms_median"),
                "outcome": a.get("outcome"),
                "distance_m": m.distance_m,
            }
        )
        r = rows[-1]
        print(
            f"seed {seed:2d}: {'reached' if r['reached'] else 'MISSED '} {r['goal_distance_m']:.2f} m from goal, "
            f"{'COLLISION' if r['collision'] else 'no collision'}, {r['cycles']} cycles, {r['outcome']}",
            flush=True,
        )
    ms = [r["cycle_ms_median"] for r in rows if r["cycle_ms_median"] is not None]
    result = {
        "runs": len(rows),
        "reached": sum(r["reached"] for r in rows),
        "collisions": sum(r["collision"] for r in rows),
        "cycle_ms_median": float(np.median(ms)) if ms else None,
        "rows": rows,
    }
    print()
    print(
        "| runs | reached within 1 m | collisions (body, or rock >= 25 cm) | GESTALT cycle ms (median) | acceptance |"
    )
    print("|---:|---:|---:|---:|---|")
    print(
        f"| {result['runs']} | {result['reached']} ({100 * result['reached'] / max(1, len(rows)):.0f} %) | "
        f"{result['collisions']} | {result['cycle_ms_median']:.1f} | >= 95 % reached, 0 collisions, <= 50 ms |"
    )
    write_json(json_path, result)
    return result
