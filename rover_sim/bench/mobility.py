"""`rover-sim bench slip`: the mobility benchmark of the default Wong–Reece law.

``bench slip --soil-model bekker`` (rover_sim/bench/slip.py) measures the earlier Bekker patch law; this module
runs every rover with ``soil_model="wong_reece"``. All on uniform slopes at the scenarios' 0.04 m
cells with the deformable terrain on (except the parked and speed rows, which say so):

* the uphill slip table (as in bench slip, but measured in the multipass steady state: see :func:`measure_slip`)
  plus a 1 deg sweep 10-32 deg and the 1 vs 5 cm/s speed effect;
* cross-slope: the rover heads along the contour (perpendicular to the gradient) for 3 m; downslope drift per
  metre of made-good travel;
* locked wheel: right-front wheel locked (Spirit from Sol 125), 2 m on flat sand; its mean sinkage over the last
  metre against the free wheels';
* ruts: 3 m straight on flat sand; mean depth of ``before - after`` on the cells under the wheels' true paths
  against the law's mean sinkage; then the rover is put back and drives the same ruts again: the second pass's
  new sinkage (below the rut) against the first pass's (below the surface it met);
* the single-wheel sinkage ratio at slip 0.6 (same load), from the law.

``LAW_NOTE`` (printed first) says which law and contact it measures.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from rover_sim.bench import write_json
from rover_sim.bench.slip import SLOPES_DEG, START_X_M, SlipRow
from rover_sim.runtime.acceptance import bars
from rover_sim.sim.drive import MAX_WHEEL_SPEED_M_S, TICK_S, Straight, execute
from rover_sim.sim.physics import RoverSim
from rover_sim.sim.soil_tables import WheelParams
from rover_sim.sim.terramechanics_wr import SAND, WheelSoilLaw
from terrains import MaterialSpec, RockSpec, RoughnessSpec, SlopeSpec, TerrainRecipe, synthesize

CELL_M = 0.04  # the scenarios' cell size
MAX_WARMUP_M = 3.0  # commanded travel after which the slip window opens even if the wheelbase is not made good
SOIL_MODEL = "wong_reece"
LAW_NOTE = (
    "Wong-Reece wheel-soil law (the default soil_model; --soil-model bekker measures the earlier patch law): the"
    " two-scale shear curve, the wheels' own cylinder contact on ground plates (sim/ground_plates.py), and the"
    " deformable terrain (opt-in in scenarios: physics.deformable = true)."
)


def slope_terrain(material: str, slope_deg: float, seed: int = 0, size_m: tuple[float, float] = (16.0, 8.0)):
    """A uniform planar slope rising toward +x, at the scenarios' cells."""
    recipe = TerrainRecipe(
        size_m=size_m,
        cell_size_m=CELL_M,
        slope=SlopeSpec(slope_deg=slope_deg, azimuth_deg=0.0),
        roughness=RoughnessSpec(rms_m=0.0),
        rocks=RockSpec(cover_fraction=0.0),
        material=MaterialSpec(kind=material),
    )
    return synthesize(recipe, seed)


def wr_sim(terrain, deform: bool = True, soil_law: bool = True) -> RoverSim:
    sim = RoverSim(terrain, soil_law=soil_law, soil_model=SOIL_MODEL)
    if deform:
        sim.enable_deformation()
    return sim


def measure_slip(
    material: str,
    slope_deg: float,
    drive_m: float = 1.5,
    warmup_m: float = 0.5,
    seed: int = 0,
    speed_m_s: float = MAX_WHEEL_SPEED_M_S,
    deform: bool = True,
    max_warmup_m: float = MAX_WARMUP_M,
) -> SlipRow:
    """Steady-state uphill slip over ``drive_m`` of commanded travel (this law, 0.04 m cells).

    The window opens once the rover has commanded ``warmup_m`` (the soil's shear state builds up) **and** made
    good its own wheelbase, so that with the deformable terrain its middle and rear wheels run in the front
    wheels' ruts (the multipass steady state, as in a MER drive of metres); or at ``max_warmup_m`` of commanded
    travel for a rover that cannot make that good (slip near or beyond 100 %). A fixed commanded warm-up instead
    measures the rear wheels on fresh soil for longer the more the rover slips, which made a cliff in slip vs
    slope near 25 deg. ``slip = 1 - made_good / commanded`` with made-good along the rover's heading.
    """
    sim = wr_sim(slope_terrain(material, slope_deg, seed), deform)
    sim.place(START_X_M, 0.0, 0.0)
    r = sim.law.radius_m
    x_axis = sim.rotation()[:, 0]
    centres = sim.wheel_centres_m() @ x_axis
    wheelbase_m = float(centres.max() - centres.min())
    p_start, a_start = sim.position_m(), sim.wheel_angles_rad().mean()
    mark: dict[str, np.ndarray] = {}

    def on_tick(s: RoverSim) -> str | None:
        commanded = (s.wheel_angles_rad().mean() - a_start) * r
        if "p0" not in mark:
            made_good = float(np.dot(s.position_m() - p_start, x_axis))
            if commanded >= warmup_m and (made_good >= wheelbase_m or commanded >= max_warmup_m):
                mark["p0"], mark["a0"], mark["x_axis"] = s.position_m(), s.wheel_angles_rad().mean(), s.rotation()[:, 0]
            return None
        return "window measured" if (s.wheel_angles_rad().mean() - mark["a0"]) * r >= drive_m else None

    execute(sim, Straight(max_warmup_m + drive_m + 0.5), speed_m_s=speed_m_s, on_tick=on_tick)
    commanded = (sim.wheel_angles_rad().mean() - mark["a0"]) * r
    made_good = float(np.dot(sim.position_m() - mark["p0"], mark["x_axis"]))
    return SlipRow(material, slope_deg, 1.0 - made_good / commanded, float(commanded), made_good)


def parked_drift_m(slope_deg: float = 30.0, hold_s: float = 60.0, seed: int = 0, material: str = "bedrock") -> float:
    """Displacement of a rover parked (wheels held) on a slope of ``material`` over ``hold_s`` (no deformation)."""
    sim = wr_sim(slope_terrain(material, slope_deg, seed), deform=False)
    sim.place(0.0, 0.0, 0.0, settle_s=2.0)
    p0 = sim.position_m()
    sim.step_for(hold_s)
    return float(np.linalg.norm(sim.position_m() - p0))


SPEED_MODES = ("law", "deform", "bare", "bare_sphere")


def physics_speed(sim_s: float = 20.0, seed: int = 0, round_s: float = 1.0) -> dict[str, float]:
    """Real-time factors driving on flat sand at the scenarios' cells: the law alone, the law with the deformable
    terrain, and bare MuJoCo (law off) of the same model and timestep, all in the same run.

    ``bare`` is ``mj_step`` alone on this law's model (wheel cylinders on their ground plates, see
    :mod:`rover_sim.sim.ground_plates`), the plates left where the settled rover put them (flat ground), so it
    costs none of our code; ``bare_sphere`` is ``mj_step`` alone on the Bekker law's model, where MuJoCo tests
    each wheel sphere against the heightfield itself (a reference: what "bare MuJoCo" of a rover on a
    heightfield costs).

    "On one core": each mode's time is the CPU time of this thread (``time.thread_time``), so other
    jobs on a shared machine do not count as our cost; the modes run interleaved, ``round_s`` of simulated time
    each in turn, so they see the same machine load, cache state and clock speed. Keys: ``law``, ``deform``,
    ``bare`` (CPU-time factors, the ones judged) and ``<mode>_wall`` (wall-clock factors of the same steps)."""
    terrain = slope_terrain("sand", 0.0, seed)
    sims = {}
    for mode in SPEED_MODES:
        if mode == "bare_sphere":
            sim = sims[mode] = RoverSim(terrain, soil_law=False)
        else:
            sim = sims[mode] = wr_sim(terrain, deform=mode == "deform", soil_law=not mode.startswith("bare"))
        sim.place(START_X_M, 0.0, 0.0, settle_s=0.5)
        if mode == "bare":
            sim.plates = None  # mj_step alone: the plates stay where they are (flat ground)
    dt = sims["bare"].timestep_s
    chunk = int(round(TICK_S / dt))
    per_round = max(int(round(round_s / (chunk * dt))), 1)  # ticks of each mode per round
    rounds = max(int(round(sim_s / (per_round * chunk * dt))), 1)
    cpu = dict.fromkeys(SPEED_MODES, 0.0)
    wall = dict.fromkeys(SPEED_MODES, 0.0)
    for _ in range(rounds):
        for mode, sim in sims.items():
            wheel_rate = np.full(6, MAX_WHEEL_SPEED_M_S / sim.law.radius_m)
            c0, w0 = time.thread_time(), time.perf_counter()
            for _ in range(per_round):
                sim.step(wheel_rate, chunk)
            cpu[mode] += time.thread_time() - c0
            wall[mode] += time.perf_counter() - w0
    simulated_s = rounds * per_round * chunk * dt
    out = {mode: simulated_s / max(cpu[mode], 1e-9) for mode in SPEED_MODES}
    out |= {f"{mode}_wall": simulated_s / max(wall[mode], 1e-9) for mode in SPEED_MODES}
    return out


W_N = 108.0  # one sixth of MER's weight on Mars


def sinkage_ratio_i06() -> float:
    law = WheelSoilLaw(n_wheels=1)
    return law.sinkage_m(W_N, 0, 0.6) / law.sinkage_m(W_N, 0, 0.0)


def cross_slope_drift_m_per_m(material: str, slope_deg: float, drive_m: float = 3.0, seed: int = 0) -> float:
    """Downslope drift per metre driven along the contour (the slope rises toward +x; the rover heads +y)."""
    sim = wr_sim(slope_terrain(material, slope_deg, seed))
    sim.place(0.0, -2.0, math.pi / 2)
    p0 = sim.position_m()
    execute(sim, Straight(drive_m), speed_m_s=MAX_WHEEL_SPEED_M_S)
    d = sim.position_m() - p0
    return float(max(-d[0], 0.0) / max(abs(d[1]), 1e-6))


def locked_wheel_sinkage_ratio(drive_m: float = 2.0, seed: int = 0) -> float:
    """Sinkage of the locked right-front wheel over the last metre / the mean of the free wheels'."""
    sim = wr_sim(slope_terrain("sand", 0.0, seed))
    sim.lock_wheels(["rf"])
    sim.place(START_X_M, 0.0, 0.0)
    x0 = sim.position_m()[0]
    zs: list[np.ndarray] = []

    def tick(s: RoverSim) -> None:
        if s.position_m()[0] - x0 > drive_m - 1.0:
            zs.append(s.wheel_soil_state().sinkage_m.copy())

    execute(sim, Straight(drive_m), speed_m_s=MAX_WHEEL_SPEED_M_S, on_tick=tick)
    z = np.mean(zs, axis=0) if zs else sim.wheel_soil_state().sinkage_m
    rf = 3  # WHEELS order lf, lm, lr, rf, rm, rr
    free = np.delete(z, rf)
    return float(z[rf] / max(free.mean(), 1e-9))


def rut_checks(drive_m: float = 3.0, seed: int = 0) -> dict[str, float]:
    """rut_depth_ratio, second_pass_sinkage_ratio, bedrock_cells_changed (on a half-bedrock strip) of 3 m drives."""
    terrain = slope_terrain("sand", 0.0, seed)
    sim = wr_sim(terrain)
    deform = sim.enable_deformation()
    sim.place(START_X_M, 0.0, 0.0)
    before = deform.heights_m()
    paths: list[np.ndarray] = []
    new1: list[float] = []
    z1: list[float] = []

    def tick(s: RoverSim, new: list[float], zs: list[float] | None) -> None:
        st = s.wheel_soil_state()
        c = s.wheel_centres_m()
        paths.append(c[:, :2].copy())
        new.append(float(np.mean(np.maximum(st.sinkage_m - np.array(s.law.presink_m), 0.0))))
        if zs is not None:
            zs.append(float(np.mean(st.sinkage_m)))

    execute(sim, Straight(drive_m), speed_m_s=MAX_WHEEL_SPEED_M_S, on_tick=lambda s: tick(s, new1, z1))
    after = deform.heights_m()
    dh = before - after
    pts = np.concatenate(paths)
    j = np.rint((pts[:, 0] + terrain.half_x_m) / terrain.cell_size_m).astype(int)
    i = np.rint((pts[:, 1] + terrain.half_y_m) / terrain.cell_size_m).astype(int)
    under = np.unique(np.stack([i, j], axis=1), axis=0)
    rut = float(dh[under[:, 0], under[:, 1]].mean())
    # second pass: back to the start (the ground keeps its ruts), the same drive
    sim.place(START_X_M, 0.0, 0.0)
    new2: list[float] = []
    execute(sim, Straight(drive_m), speed_m_s=MAX_WHEEL_SPEED_M_S, on_tick=lambda s: tick(s, new2, None))
    return {
        "rut_depth_m": rut,
        "law_mean_sinkage_m": float(np.mean(z1)),
        "rut_depth_ratio": rut / max(float(np.mean(z1)), 1e-9),
        "second_pass_sinkage_ratio": float(np.mean(new2) / max(np.mean(new1), 1e-9)),
        "berm_volume_ratio": float(-dh[dh < 0].sum() / max(dh[dh > 0].sum(), 1e-12)),
    }


def bedrock_unchanged(drive_m: float = 2.0, seed: int = 0) -> bool:
    """A drive on bedrock leaves the heightfield byte-identical."""
    sim = wr_sim(slope_terrain("bedrock", 0.0, seed))
    deform = sim.enable_deformation()
    sim.place(START_X_M, 0.0, 0.0)
    before = deform.heights_m()
    execute(sim, Straight(drive_m), speed_m_s=MAX_WHEEL_SPEED_M_S)
    return bool(before.tobytes() == deform.heights_m().tobytes())


def plot(path: str, rows: list[dict], slips_fine: dict[float, float]) -> None:
    """DP/W vs slip (MER wheel and the rigid-wheel Wong-Reece reference) and slip vs slope with the MER points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    s = np.linspace(0.0, 1.0, 101)
    for label, wheel in (
        ("MER wheel (law)", None),
        ("rigid smooth wheel (Wong-Reece reference)", WheelParams(grouser_height_m=0.0, flat_patch_m=0.0)),
    ):
        law = WheelSoilLaw(n_wheels=1, wheel=wheel)
        dp = [law.lookup(0, W_N, x)[1] - law.lookup(0, W_N, x)[2] for x in s]
        a.plot(s, dp, label=label)
    a.axhline(math.tan(math.radians(SAND.friction_angle_deg)), color="grey", ls=":", label="tan(phi)")
    a.set_xlabel("slip")
    a.set_ylabel("drawbar pull / load")
    a.set_title(f"single wheel on sand, load {W_N:.0f} N")
    a.legend(fontsize=8)
    a.grid(alpha=0.3)
    sand = sorted((r["slope_deg"], r["slip"]) for r in rows if r["material"] == "sand")
    rock = sorted((r["slope_deg"], r["slip"]) for r in rows if r["material"] == "bedrock")
    fine = sorted(slips_fine.items())
    if fine:
        b.plot(
            [f[0] for f in fine], [100 * f[1] for f in fine], ".", color="tab:orange", ms=4, label="sand, 1 deg steps"
        )
    b.plot([x[0] for x in sand], [100 * x[1] for x in sand], "o-", color="tab:orange", label="sand (sim)")
    b.plot([x[0] for x in rock], [100 * x[1] for x in rock], "s-", color="tab:brown", label="bedrock (sim)")
    mer = [(17, 50, "Eagle"), (19, 50, "Endurance"), (32, 99.5, "scree 32 deg"), (26, 125, "Spirit Sol 206 (>25 deg)")]
    for x, y, name in mer:
        b.plot(x, y, "k*", ms=10)
        b.annotate(name, (x, y), textcoords="offset points", xytext=(4, -10), fontsize=7)
    b.axhspan(40, 65, xmin=17 / 35, xmax=20 / 35, color="green", alpha=0.15)
    b.set_xlim(0, 35)
    b.set_ylim(-5, 140)
    b.set_xlabel("slope (deg), uphill")
    b.set_ylabel("slip (%)")
    b.set_title("slip vs slope at 5 cm/s, MER points (stars)")
    b.legend(fontsize=8, loc="upper left")
    b.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fine_sweep(seed: int) -> dict[float, float]:
    return {float(a): measure_slip("sand", float(a), seed=seed).slip for a in range(10, 33)}


def run(json_path: str | None = None, seed: int = 0, png_path: str | None = "runs/bench_slip.png") -> dict:
    """`rover-sim bench slip --soil-model wong_reece`: the slip table, the held-out mobility checks, speed."""
    print(f"> {LAW_NOTE}\n", flush=True)
    rows = [measure_slip(m, a, seed=seed) for m in ("sand", "bedrock") for a in SLOPES_DEG]
    fine = _fine_sweep(seed)
    steps = [abs(fine[a + 1] - fine[a]) for a in np.arange(10.0, 25.0)]
    back = next((a for a in np.arange(25.0, 33.0) if fine[a] >= 1.0), None)
    speed = {}
    for a in (15.0, 20.0):
        slow = measure_slip("sand", a, seed=seed, speed_m_s=0.01).slip
        fast = measure_slip("sand", a, seed=seed).slip
        speed[f"{a:.0f}"] = 100 * abs(slow - fast)
    drift_rock = parked_drift_m(seed=seed)
    drift_sand = parked_drift_m(seed=seed, material="sand")
    cross = {
        "sand": {f"{a}": cross_slope_drift_m_per_m("sand", a, seed=seed) for a in (10, 15, 20, 25)},
        "bedrock": {"20": cross_slope_drift_m_per_m("bedrock", 20, seed=seed)},
    }
    locked = locked_wheel_sinkage_ratio(seed=seed)
    ruts = rut_checks(seed=seed)
    rock_same = bedrock_unchanged(seed=seed)
    sink = sinkage_ratio_i06()
    rates = physics_speed(seed=seed)
    rtf, rtf_def, rtf_bare = rates["law"], rates["deform"], rates["bare"]

    result = {
        "soil_model": SOIL_MODEL,
        "experimental": False,
        "slip": [{"material": r.material, "slope_deg": r.slope_deg, "slip": r.slip} for r in rows],
        "slip_fine_sand": {f"{a:.0f}": s for a, s in fine.items()},
        "realtime_factor": rtf,
        "bare_mujoco_ratio": rtf / rtf_bare,
        "bare_realtime_factor": rtf_bare,
        "parked_30deg_bedrock_drift_m": drift_rock,
        "sand_monotonic": bool(np.all(np.diff([r.slip for r in rows if r.material == "sand"]) > 0)),
        "cell_size_m": CELL_M,
        "speed_effect_pp": speed,
        "max_step_pp_10_25": 100 * max(steps),
        "backslide_slope_deg": back,
        "sinkage_ratio_i06": sink,
        "parked_30deg_sand_drift_m": drift_sand,
        "cross_slope_drift_m_per_m": cross,
        "locked_wheel_sinkage_ratio": locked,
        "rut_depth_ratio": ruts["rut_depth_ratio"],
        "second_pass_sinkage_ratio": ruts["second_pass_sinkage_ratio"],
        "bedrock_unchanged": rock_same,
        "deformation_realtime_factor": rtf_def,
        "deformation_bare_ratio": rtf_def / rtf_bare,
        "speed_wall_clock": {mode: rates[f"{mode}_wall"] for mode in SPEED_MODES},
        "bare_sphere_realtime_factor": rates["bare_sphere"],
        "ruts": ruts,
        "rows": [asdict(r) for r in rows],
    }
    # the one judge (rover_sim.runtime.acceptance): these tables, the JSON, the JUnit and the exit status
    verdict = bars.mobility_verdict(result)
    print("| material | slope (deg) | slip (%) | published anchor / acceptance | ok |")
    print("|---|---:|---:|---|---|")
    for r, c in zip(rows, verdict.checks, strict=False):  # the verdict's first checks are the rows, in order
        print(f"| {r.material} | {r.slope_deg:.0f} | {100 * r.slip:.1f} | {c.bar} | {c.cell()} |")
    print()
    print("| sand slope (deg) | " + " | ".join(f"{a:.0f}" for a in fine) + " |")
    print("|---|" + "---:|" * len(fine))
    print("| slip (%) | " + " | ".join(f"{100 * s:.0f}" for s in fine.values()) + " |")
    print()
    reported = [  # figures shown beside the checks, not judged
        ("cell size", f"{CELL_M} m", "0.04 m (the scenarios')"),
        ("berm volume / rut volume", f"{ruts['berm_volume_ratio']:.2f}", "about 1"),
        ("real-time factor, law + deformation, by wall clock (shared machine: load-dependent)",
         f"{rates['deform_wall']:.0f}x", "-"),
        ("real-time factor, law only / bare MuJoCo", f"{rtf:.0f}x / {rtf_bare:.0f}x", "-"),
        ("bare MuJoCo with its own sphere-heightfield wheel contact (the Bekker law's model)",
         f"{rates['bare_sphere']:.0f}x", "-"),
    ]  # fmt: skip
    print("| check | measured | acceptance | ok |")
    print("|---|---:|---|---|")
    for c in verdict.checks[len(rows) :]:
        print(f"| {c.name} | {c.measured} | {c.bar} | {c.cell()} |")
    for name, val, acc in reported:
        print(f"| {name} | {val} | {acc} | reported |")
    result |= {
        "checks": [{"name": c.name, "measured": c.measured, "acceptance": c.bar, "ok": c.passed, "why": c.why}
                   for c in verdict.checks[len(rows):]],
        "reported": [{"name": n, "measured": v, "acceptance": a} for n, v, a in reported],
        "all_pass": verdict.passed,
        "reasons": verdict.reasons,
    }  # fmt: skip
    write_json(json_path, result)
    if png_path:
        Path(png_path).parent.mkdir(parents=True, exist_ok=True)
        plot(png_path, result["slip"], fine)
        print(f"\nplot: {png_path}")
    return result
