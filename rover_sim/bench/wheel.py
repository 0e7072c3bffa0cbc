"""`rover-sim bench wheel`: the wheel–soil law on a single-wheel rig, scored against measured single-wheel tests.

Every row of the data (default: the CMU tests, ``benchmarks/data/cmu_single_wheel``) is run on the rig
(:mod:`rover_sim.sim.wheel_rig`: the rover's own law, ground plate and deformable heightfield) at the row's slip,
slip angle, measured load and carriage speed, in a fresh soil bin of the laboratory soil
(:data:`rover_sim.sim.terramechanics_wr.CMU_SAND`). Scored per wheel: the RMSE of drawbar pull / load, lateral
force / load and sinkage over each cumulative slip-angle band, and, at 0 deg, a sweep of slip from -1 to 0.9 at the
wheel's mean load whose drawbar pull must not fall (the bars: :class:`rover_sim.runtime.acceptance.bars.WheelBar`).
Prints the tables, writes ``--json`` (one row per input row, in input order) and a PNG grid (measured mean ± std of
the trials against the rig, one panel per slip angle and quantity).
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from rover_sim.bench import write_json
from rover_sim.bench.wheel_data import WheelTest, read_tests
from rover_sim.runtime.acceptance import bars
from rover_sim.sim.soil_tables import SoilParams
from rover_sim.sim.terramechanics_wr import CMU_SAND
from rover_sim.sim.wheel_rig import RigResult, RigRun, WheelRig

QUANTITIES = {  # JSON name -> (row key predicted, measured key, per load?)
    "drawbar_over_load": ("drawbar_pull_N", True),
    "lateral_over_load": ("lateral_force_N", True),
    "sinkage_mm": ("sinkage_mm", False),
}
SWEEP_SLIPS = tuple(float(s) for s in np.round(np.linspace(-1.0, 0.9, 20), 3))  # the 0 deg monotonicity sweep


def run_rows(tests: list[WheelTest], soil: SoilParams = CMU_SAND, progress: bool = True) -> list[RigResult]:
    """The rig's steady-window result for every test row (a fresh bin each)."""
    rigs: dict[str, WheelRig] = {}
    out = []
    for k, t in enumerate(tests):
        rig = rigs.setdefault(repr(t.geometry), WheelRig(t.geometry, soil))
        out.append(rig.run(RigRun(t.slip, t.slip_angle_deg, t.load_n, t.travel_speed_m_s)))
        if progress and (k + 1) % 24 == 0:
            print(f"  rig: {k + 1}/{len(tests)} rows", flush=True)
    return out


def monotone_sweep(test: WheelTest, load_n: float, soil: SoilParams = CMU_SAND) -> list[tuple[float, float]]:
    """(slip, drawbar pull / load) of the rig at 0 deg over ``SWEEP_SLIPS`` at ``load_n``."""
    rig = WheelRig(test.geometry, soil)
    return [(s, rig.run(RigRun(s, 0.0, load_n, test.travel_speed_m_s)).drawbar_pull_n / load_n) for s in SWEEP_SLIPS]


def largest_drop(curve: list[tuple[float, float]]) -> float:
    """The largest fall of the value between successive points (0 when it never falls)."""
    return max([0.0] + [a[1] - b[1] for a, b in zip(curve, curve[1:], strict=False)])


def _row_json(t: WheelTest, r: RigResult) -> dict:
    return {"wheel": t.wheel, "slip_angle_deg": t.slip_angle_deg, "slip": t.slip, "load_N": t.load_n,
            "drawbar_pull_N": r.drawbar_pull_n, "lateral_force_N": r.lateral_force_n,
            "sinkage_mm": 1000.0 * r.sinkage_m, "torque_Nm": r.torque_nm, "measured": t.measured}  # fmt: skip


def _errors(rows: list[dict], quantity: str) -> list[float]:
    key, per_load = QUANTITIES[quantity]
    out = []
    for r in rows:
        m = (r["measured"] or {}).get(key)
        if m is not None:
            scale = r["load_N"] if per_load else 1.0
            out.append((r[key] - m) / scale)
    return out


def _rmse(errors: list[float]) -> float | None:
    return float(math.sqrt(np.mean(np.square(errors)))) if errors else None


def score(rows: list[dict]) -> tuple[dict, dict]:
    """(per wheel: RMSE by cumulative band; over all rows: RMSE overall and by slip angle)."""
    wheels: dict[str, dict] = {}
    for name in dict.fromkeys(r["wheel"] for r in rows):
        mine = [r for r in rows if r["wheel"] == name]
        wheels[name] = {
            band.key: {
                q: _rmse(_errors([r for r in mine if r["slip_angle_deg"] <= band.max_slip_angle_deg], q))
                for q in QUANTITIES
            }  # fmt: skip
            for band in bars.WHEEL.bands
        }
    angles = sorted({r["slip_angle_deg"] for r in rows})
    overall = {
        q: {
            "all": _rmse(_errors(rows, q)),
            "by_slip_angle": {
                f"{a:g}": _rmse(_errors([r for r in rows if r["slip_angle_deg"] == a], q)) for a in angles
            },
        }  # fmt: skip
        for q in QUANTITIES
    }
    return wheels, overall


def bench_wheel(data: str | Path | None = None, json_path: str | None = None, wheel: str | None = None,
                png_path: str | None = "runs/bench_wheel.png", soil: SoilParams = CMU_SAND) -> dict:  # fmt: skip
    """Run, score, print and write ``bench wheel`` (see the module docstring); returns the JSON document."""
    tests = read_tests(data, wheel)
    print(f"> {len(tests)} rows of {data or 'the CMU single-wheel tests'}; soil {soil.name}; each row on the rig "
          "(the rover's Wong-Reece law, ground plate and deformable heightfield)\n", flush=True)  # fmt: skip
    results = run_rows(tests, soil)
    rows = [_row_json(t, r) for t, r in zip(tests, results, strict=True)]
    by_band, overall = score(rows)
    sweeps: dict[str, list[tuple[float, float]]] = {}
    for name in by_band:
        zero = [t for t in tests if t.wheel == name and t.slip_angle_deg == 0.0]
        if zero:
            sweeps[name] = monotone_sweep(zero[0], float(np.mean([t.load_n for t in zero])), soil)
    drops = {name: largest_drop(curve) for name, curve in sweeps.items()}
    passed, reasons = bars.judge_wheel(by_band, drops)
    geometry = {t.wheel: asdict(t.geometry) for t in tests}
    result = {
        "soil": soil.name,
        "wheels": {n: {"geometry": geometry[n], "rmse_by_band": by_band[n]} for n in by_band},
        "passed": passed,
        "reasons": reasons,
        "rows": rows,
        "rmse": overall,
    }
    _print(result, sweeps, drops)
    write_json(json_path, result)
    if png_path:
        Path(png_path).parent.mkdir(parents=True, exist_ok=True)
        plot(png_path, tests, rows, sweeps)
        print(f"\nplot: {png_path}")
    return result


def _fmt(v: float | None, digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def _print(result: dict, sweeps: dict, drops: dict) -> None:
    bar = bars.WHEEL
    print("| wheel | slip angles | drawbar / load RMSE | lateral / load RMSE | sinkage RMSE (mm) | bar | ok |")
    print("|---|---|---:|---:|---:|---|:-:|")
    for name, w in result["wheels"].items():
        for band in bar.bands:
            got = w["rmse_by_band"][band.key]
            ok = all(got[q] is None or got[q] <= getattr(band, q) for q in bars.WHEEL_QUANTITIES)
            print(f"| {name} | {band.key} deg | {_fmt(got['drawbar_over_load'])} | {_fmt(got['lateral_over_load'])} "
                  f"| {_fmt(got['sinkage_mm'], 1)} | <= {band.drawbar_over_load:g} / {band.lateral_over_load:g} / "
                  f"{band.sinkage_mm:g} mm | {'yes' if ok else 'NO'} |")  # fmt: skip
    print()
    print("| slip angle (deg) | drawbar / load RMSE | lateral / load RMSE | sinkage RMSE (mm) |  (both wheels)")
    print("|---:|---:|---:|---:|")
    rm = result["rmse"]
    for a in rm["drawbar_over_load"]["by_slip_angle"]:
        dp, lat, z = (rm[q]["by_slip_angle"][a] for q in bars.WHEEL_QUANTITIES)
        print(f"| {a} | {_fmt(dp)} | {_fmt(lat)} | {_fmt(z, 1)} |")
    print()
    for name, curve in sweeps.items():
        vals = " ".join(f"{v:+.3f}" for _, v in curve)
        ok = drops[name] <= bar.monotone_tolerance
        print(
            f"0 deg sweep, {name}: DP/load at slip {curve[0][0]:g} .. {curve[-1][0]:g}: {vals} "
            f"(largest fall {drops[name]:.4f}; bar <= {bar.monotone_tolerance:g}: {'yes' if ok else 'NO'})"
        )
    print(f"\nbench wheel: {'PASS' if result['passed'] else 'FAIL'}" +
          ("" if result["passed"] else " (" + "; ".join(result["reasons"]) + ")"))  # fmt: skip


def plot(path: str, tests: list[WheelTest], rows: list[dict], sweeps: dict) -> None:
    """The grid: one column per slip angle, one row per quantity; measured mean ± std of each condition's trials
    (points) and the rig (lines: the rows' predictions averaged per condition; dotted at 0 deg: the sweep)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    angles = sorted({t.slip_angle_deg for t in tests})
    names = list(dict.fromkeys(t.wheel for t in tests))
    colours = dict(zip(names, ["tab:orange", "tab:blue", "tab:green", "tab:red", "tab:purple"], strict=False))
    fig, axes = plt.subplots(3, len(angles), figsize=(3.6 * len(angles), 8.4), squeeze=False, sharex=True,
                             layout="constrained")  # fmt: skip
    labels = ("drawbar pull / load", "lateral force / load", "sinkage (mm)")
    for col, a in enumerate(angles):
        for name in names:
            conds: dict[str, list[int]] = {}
            for k, t in enumerate(tests):
                if t.wheel == name and t.slip_angle_deg == a:
                    conds.setdefault(t.condition, []).append(k)
            pts = []
            for ks in conds.values():
                slip = float(np.mean([tests[k].slip for k in ks]))
                pred, meas = [], []
                for key, per_load in QUANTITIES.values():
                    scale = [rows[k]["load_N"] if per_load else 1.0 for k in ks]
                    pred.append(float(np.mean([rows[k][key] / s for k, s in zip(ks, scale, strict=True)])))
                    m = [(rows[k]["measured"] or {}).get(key) for k in ks]
                    m = [v / s for v, s in zip(m, scale, strict=True) if v is not None]
                    meas.append((float(np.mean(m)), float(np.std(m, ddof=1)) if len(m) > 1 else 0.0) if m else None)
                pts.append((slip, pred, meas))
            pts.sort()
            for q in range(3):
                ax = axes[q, col]
                ax.plot([p[0] for p in pts], [p[1][q] for p in pts], "-", color=colours[name], lw=1.6,
                        label=f"{name}: rig" if (q, col) == (0, 0) else None)  # fmt: skip
                m = [(p[0], p[2][q]) for p in pts if p[2][q] is not None]
                if m:
                    ax.errorbar([x for x, _ in m], [v[0] for _, v in m], yerr=[v[1] for _, v in m], fmt="o", ms=4,
                                color=colours[name], mfc="white", capsize=2,
                                label=f"{name}: measured (mean ± std)" if (q, col) == (0, 0) else None)  # fmt: skip
            if a == 0.0 and name in sweeps:
                axes[0, col].plot(*zip(*sweeps[name], strict=True), ":", color=colours[name], lw=1.0)
    for col, a in enumerate(angles):
        axes[0, col].set_title(f"slip angle {a:g} deg")
        axes[2, col].set_xlabel("slip")
        for q in range(3):
            axes[q, col].grid(alpha=0.3)
            axes[q, 0].set_ylabel(labels[q])
    axes[0, 0].legend(fontsize=7, loc="upper left")
    fig.suptitle("bench wheel: the single-wheel rig (the rover's wheel-soil law in a soil bin) against the measured "
                 "tests; dotted at 0 deg: the monotonicity sweep", fontsize=10)  # fmt: skip
    fig.savefig(path, dpi=100)
    plt.close(fig)
