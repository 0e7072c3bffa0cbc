"""``rover-sim bench globalloc``: global localisation against orbital products over four terrain types.

For every terrain (:mod:`rover_sim.bench.globalloc_sites`) and seed: the site's orbital products
(:mod:`rover_sim.orbital.products`, the registration error at its default sigma), then at each stop a navcam
panorama (:mod:`rover_sim.orbital.panorama`, flight sensor profile) and a prior drawn 2-35 m off in position
(uniform distance, uniform direction) and +-3 deg in yaw (uniform), with the prior covariance the localiser is
told: 12 m per axis (3 sigma = 36 m) and 1.75 deg (the std of the yaw draw). Every localiser (the built-in, plugins)
gets the same stops; errors are against the truth in the site frame (the map's registration error included).
Panoramas are cached (``--cache``) so that localisers can be compared without rendering again.
The verdict: :func:`rover_sim.runtime.bars.judge_globalloc`.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from nav.camera import StereoRig
from nav.globalloc import OrbitalMap, PanoramaView
from rover_sim.bench import write_json
from rover_sim.bench.globalloc_sites import TERRAINS, site_scenario, stops_xy_yaw
from rover_sim.runtime.acceptance import bars

PRIOR_MIN_M, PRIOR_MAX_M, PRIOR_YAW_DEG = 2.0, 35.0, 3.0
PRIOR_SIGMA_M, PRIOR_SIGMA_YAW_DEG = 12.0, 1.75
PANORAMA_PX = 512  # panorama pairs rendered at 512 px (the flight navcam's 1024 px binned 2x2)
STOPS_PER_SEED = 5


@dataclass
class Stop:
    """One stop: the panorama, the onboard attitude, the prior and the truth (evaluation only)."""

    terrain: str
    seed: int
    index: int
    views: list[PanoramaView]
    R_world_rover: np.ndarray
    prior_xy_yaw: np.ndarray
    truth_xy_yaw: np.ndarray


@dataclass
class StopResult:
    terrain: str
    seed: int
    index: int
    prior_error_m: float
    accepted: bool
    fix_error_m: float | None
    yaw_error_deg: float | None
    sigma_m: float | None
    compute_s: float
    reason: str
    candidate_error_m: float | None = None  # the refused best hypothesis's error (None: the localiser gave none)


def draw_prior(seed: int, index: int, truth: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng([int(seed), 0x9A10, int(index)])
    d, a = rng.uniform(PRIOR_MIN_M, PRIOR_MAX_M), rng.uniform(-math.pi, math.pi)
    dyaw = math.radians(rng.uniform(-PRIOR_YAW_DEG, PRIOR_YAW_DEG))
    return np.array([truth[0] + d * math.cos(a), truth[1] + d * math.sin(a), truth[2] + dyaw])


def prior_covariance() -> np.ndarray:
    return np.diag([PRIOR_SIGMA_M**2, PRIOR_SIGMA_M**2, math.radians(PRIOR_SIGMA_YAW_DEG) ** 2])


# ------------------------------------------------------------------------------------------------ acquisition
def acquire_site(terrain: str, seed: int, n_stops: int, cache: Path, progress=print) -> tuple[OrbitalMap, list[Stop]]:  # noqa: ANN001
    """The site's orbital map and its stops (from ``cache`` when there)."""
    path = cache / f"{terrain}_{seed}.npz"
    if path.is_file():
        return load_site(path)
    from rover_sim.apps.survey import RockSiteSurvey, SurveyConfig
    from rover_sim.orbital.panorama import gentle_spot, onboard_attitude, place_rover, take_panorama, true_pose_xy_yaw
    from rover_sim.orbital.products import make_products, site_boxes
    from rover_sim.scenario.loading import scenario_from_dict

    xyyaw = stops_xy_yaw(seed, n_stops)
    sc = scenario_from_dict(site_scenario(terrain, seed, xyyaw), source=f"bench globalloc {terrain}")
    t0 = time.perf_counter()
    omap, _reg = make_products(sc, site_boxes(sc)[0])
    progress(f"{terrain} seed {seed}: orbital products in {time.perf_counter() - t0:.0f} s")
    stops = []
    cfg = SurveyConfig(resolution_px=PANORAMA_PX, render_oversample=1.0, focal_check=False)
    with RockSiteSurvey(sc, cfg) as survey:
        for k, (x, y, yaw) in enumerate(xyyaw):
            t0 = time.perf_counter()
            x, y = gentle_spot(survey.terrain, float(x), float(y))  # the rover parks on gentle ground
            place_rover(survey, float(x), float(y), float(yaw))
            views = take_panorama(survey)
            truth = true_pose_xy_yaw(survey)
            prior = draw_prior(seed, k, truth)
            R = onboard_attitude(survey, float(prior[2]))
            stops.append(Stop(terrain, seed, k, views, R, prior, truth))
            progress(f"{terrain} seed {seed} stop {k}: panorama in {time.perf_counter() - t0:.0f} s")
    save_site(path, omap, stops)
    return omap, stops


def save_site(path: Path, omap: OrbitalMap, stops: list[Stop]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict = {"image": omap.image.values, "dem": omap.dem.values}
    meta = {"image": [omap.image.x0_m, omap.image.y0_m, omap.image.px_m],
            "dem": [omap.dem.x0_m, omap.dem.y0_m, omap.dem.px_m], "sun": omap.sun_direction_map.tolist(),
            "errors": [omap.dem_sigma_m, omap.registration_sigma_m, omap.registration_sigma_rad, omap.psf_sigma_px],
            "stops": []}  # fmt: skip
    for s in stops:
        meta["stops"].append({"terrain": s.terrain, "seed": s.seed, "index": s.index, "n_views": len(s.views),
                              "rigs": [v.rig.to_dict() for v in s.views]})  # fmt: skip
        arrays[f"R_{s.index}"], arrays[f"prior_{s.index}"], arrays[f"truth_{s.index}"] = (
            s.R_world_rover, s.prior_xy_yaw, s.truth_xy_yaw)  # fmt: skip
        for j, v in enumerate(s.views):
            arrays[f"L_{s.index}_{j}"], arrays[f"Rt_{s.index}_{j}"] = v.left_u8, v.right_u8
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, meta=json.dumps(meta), **arrays)
    os.replace(tmp, path)


def load_site(path: Path) -> tuple[OrbitalMap, list[Stop]]:
    from nav.globalloc import Raster

    z = np.load(path)
    meta = json.loads(str(z["meta"]))
    e = meta["errors"]
    omap = OrbitalMap(Raster(z["image"], *meta["image"]), Raster(z["dem"], *meta["dem"]),
                      np.asarray(meta["sun"]), e[0], e[1], e[2], e[3])  # fmt: skip
    stops = []
    for m in meta["stops"]:
        k = m["index"]
        views = [PanoramaView(z[f"L_{k}_{j}"], z[f"Rt_{k}_{j}"], StereoRig.from_dict(m["rigs"][j]))
                 for j in range(m["n_views"])]  # fmt: skip
        stops.append(Stop(m["terrain"], m["seed"], k, views, z[f"R_{k}"], z[f"prior_{k}"], z[f"truth_{k}"]))
    return omap, stops


# ------------------------------------------------------------------------------------------------ evaluation
def wrap_deg(a_rad: float) -> float:
    return math.degrees((a_rad + math.pi) % (2 * math.pi) - math.pi)


def run_stop(localizer: object, stop: Stop, omap: OrbitalMap) -> StopResult:
    """One localiser at one stop: CPU time of the call (all threads: one core's worth), errors vs the truth."""
    t0 = time.process_time()
    res = localizer.localize(stop.views, stop.R_world_rover, stop.prior_xy_yaw, prior_covariance(), omap)  # type: ignore[attr-defined]
    cpu = time.process_time() - t0
    prior_err = float(np.hypot(*(stop.prior_xy_yaw[:2] - stop.truth_xy_yaw[:2])))
    if res.status != "ok":
        cand = getattr(res, "diagnostics", {}).get("candidate_xy_yaw")
        t = stop.truth_xy_yaw
        cand_err = None if cand is None else float(np.hypot(cand[0] - t[0], cand[1] - t[1]))
        return StopResult(stop.terrain, stop.seed, stop.index, prior_err, False, None, None, None, cpu, res.reason,
                          cand_err)  # fmt: skip
    xy = np.asarray(res.xy_yaw, float)
    sig = float(math.sqrt(max(np.linalg.eigvalsh(np.asarray(res.covariance)[:2, :2]).max(), 0.0)))
    err = float(np.hypot(*(xy[:2] - stop.truth_xy_yaw[:2])))
    return StopResult(stop.terrain, stop.seed, stop.index, prior_err, True, err, wrap_deg(xy[2] - stop.truth_xy_yaw[2]),
                      sig, cpu, "")  # fmt: skip


def summarise(rows: list[StopResult]) -> dict:
    """The per-terrain block of the JSON (errors over accepted fixes)."""
    errs = [r.fix_error_m for r in rows if r.accepted and r.fix_error_m is not None]
    fixed = sum(1 for r in rows if r.accepted)
    return {
        "stops": len(rows),
        "fixed": fixed,
        "refused": len(rows) - fixed,
        "false_fixes": sum(1 for e in errs if e > bars.GLOBALLOC.false_fix_m),
        "median_error_m": float(np.median(errs)) if errs else None,
        "p90_error_m": float(np.percentile(errs, 90)) if errs else None,
        "compute_s_median": float(np.median([r.compute_s for r in rows])) if rows else None,
        "success": sum(1 for e in errs if e <= bars.GLOBALLOC.false_fix_m),
        "seeds": sorted({r.seed for r in rows}),
    }


def bench_globalloc(
    json_path: str | None = None,
    localizers: list[str] | None = None,
    seeds: list[int] | None = None,
    terrains: list[str] | None = None,
    stops_per_seed: int = STOPS_PER_SEED,
    cache: str | Path = "runs/globalloc_cache",
) -> dict:
    from rover_sim.runtime.plugins import make_global_localizer

    names = ["builtin", *(localizers or [])]
    impls = {n: make_global_localizer(n) for n in names}
    seeds = list(seeds) if seeds else list(range(100, 108))
    terrains = list(terrains or TERRAINS)
    rows: dict[str, list[StopResult]] = {n: [] for n in names}
    load = os.getloadavg()
    for seed in seeds:  # seed-major: an interrupted run has seen every terrain
        for terrain in terrains:
            omap, stops = acquire_site(terrain, seed, stops_per_seed, Path(cache))
            for stop in stops:
                for n, impl in impls.items():
                    r = run_stop(impl, stop, omap)
                    rows[n].append(r)
                    err = f"{r.fix_error_m:.2f} m" if r.accepted else f"refused ({r.reason})"
                    print(f"  {n} {terrain} seed {seed} stop {stop.index}: prior {r.prior_error_m:.1f} m -> {err}, "
                          f"{r.compute_s:.1f} CPU-s", flush=True)  # fmt: skip
    out: dict = {"passed": True, "reasons": [], "localizers": {}, "traverse_1km": None}
    for n in names:
        blocks = {t: summarise([r for r in rows[n] if r.terrain == t]) for t in terrains}
        total = sum(b["stops"] for b in blocks.values())
        success = sum(b["success"] for b in blocks.values()) / max(total, 1)
        passed, reasons = bars.judge_globalloc(blocks)
        out["localizers"][n] = {"terrains": {t: {k: v for k, v in b.items() if k not in ("seeds", "success")}
                                             for t, b in blocks.items()}, "success_rate": success}  # fmt: skip
        out["passed"] &= passed
        out["reasons"] += [f"{n}: {r}" for r in reasons]
    print_table(out, seeds, load)
    write_json(json_path, out)
    if json_path:
        details = {"seeds": seeds, "stops_per_seed": stops_per_seed, "load_average_at_start": load,
                   "profile": "flight", "panorama_px": PANORAMA_PX,
                   "traverse_1km": "not measured: the in-loop fixes are not part of the mission runner yet",
                   "stops": {n: [asdict(r) for r in rows[n]] for n in names}}  # fmt: skip
        Path(str(json_path) + ".details.json").write_text(json.dumps(details, indent=2))
    return out


def table_markdown(out: dict) -> str:
    """The bench's markdown table from its JSON (the docs page's table is generated with this)."""
    lines = ["| localiser | terrain | stops | fixed | refused | false fixes | median m | p90 m | CPU s (median) |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    for n, loc in out["localizers"].items():
        for t, b in loc["terrains"].items():
            med = "-" if b["median_error_m"] is None else f"{b['median_error_m']:.3f}"
            p90 = "-" if b["p90_error_m"] is None else f"{b['p90_error_m']:.3f}"
            cpu = "-" if b["compute_s_median"] is None else f"{b['compute_s_median']:.1f}"
            lines.append(f"| {n} | {t} | {b['stops']} | {b['fixed']} | {b['refused']} | {b['false_fixes']} | {med} "
                         f"| {p90} | {cpu} |")  # fmt: skip
        lines.append(f"| {n} | success rate (accepted and within 1 m, all terrains) | | | | | | | "
                     f"{loc['success_rate']:.2f} |")  # fmt: skip
    return "\n".join(lines)


def print_table(out: dict, seeds: list[int], load: tuple) -> None:
    print(f"\nbench globalloc: flight profile, seeds {seeds[0]}-{seeds[-1]} ({len(seeds)}), load average at start "
          f"{load[0]:.1f}; errors against truth in the site frame")  # fmt: skip
    print(table_markdown(out))
    print("traverse_1km: null (fixes in the mission loop are not wired yet; the 1 km case is not measured)")
    print("PASSED" if out["passed"] else "FAILED:\n  " + "\n  ".join(out["reasons"]))
