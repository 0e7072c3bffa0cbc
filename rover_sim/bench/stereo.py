"""`rover-sim bench stereo`: MER SAD stereo vs plain OpenCV StereoBM on simulated hazcam pairs with ground truth.

Pairs are rendered at 256x256 (MER's binned navigation images) and at 1024x1024 (full resolution) from the front
hazcams on seeded sand and bedrock terrains with rocks; ground-truth disparity ``fx B / Z`` comes from the rendered
depth. Scored pixels: terrain or rock (not the rover itself) with ground-truth depth within 3 m. ``density`` =
fraction of scored pixels that get a disparity; ``bad1`` = fraction of those more than 1 px off. Both algorithms run
on the same pairs in the same process, their runs interleaved (the machine may be shared); time is the median of
the per-pair medians. Each pair is also run once with the other SAD engine (``nav.stereo`` has two, see
:func:`nav.stereo.sad_engine`), untimed: the two must give the same disparity bit for bit, or the bench fails.

The pairs come from :func:`pairs_for_profile`: ``"ideal"`` renders rectified pinhole pairs directly; ``"flight"``
renders raw (distorted, CCD-formed) pairs and rectifies them with the onboard calibration, with ground truth from
the true correspondence (:mod:`rover_sim.bench.stereo_flight`).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from nav.camera import StereoRig
from nav.stereo import (
    StereoParams,
    compute_disparity,
    pipeline_threads,
    sad_engine,
    stereobm_baseline,
)
from rover_sim.bench import write_json
from rover_sim.bench.stereo_flight import render_flight_pair
from rover_sim.errors import ConfigError
from rover_sim.render.config import ImageNoise, RenderConfig
from rover_sim.render.renderer import StereoRenderer, terrain_texture
from rover_sim.runtime.acceptance import bars
from rover_sim.sim.physics import RoverSim
from terrains import MaterialSpec, RockSpec, RoughnessSpec, TerrainRecipe, synthesize

MAX_RANGE_M = 3.0
NUM_DISPARITIES = 32  # hazcam at 256^2: fx ~68 px, B 0.1 m -> 0.35 m range at 20 px
RESOLUTIONS_PX = (256, 1024)
OTHER_ENGINE = {"fused": "opencv", "opencv": "fused"}  # the cross-check of each pair
PROFILES = ("ideal", "flight")


def params_for(resolution_px: int) -> StereoParams:
    """The 256 px parameters (32 disparities) scaled to ``resolution_px`` (:meth:`StereoParams.for_resolution`)."""
    return StereoParams(num_disparities=NUM_DISPARITIES).for_resolution(resolution_px)


def num_disparities(resolution_px: int) -> int:
    """The same range in metres at every resolution: 32 at 256 px, 128 at 1024 px (a multiple of 16)."""
    return params_for(resolution_px).num_disparities


@dataclass(frozen=True)
class SimPair:
    left: np.ndarray
    right: np.ndarray
    gt_disparity_px: np.ndarray  # NaN where not scored
    rig: StereoRig
    label: str


def pairs_for_profile(profile: str, resolution_px: int, seeds=(0, 1, 2)) -> list[SimPair]:
    """The rectified pairs ``bench stereo`` scores for a sensor profile (``[sensors] profile``): ``"ideal"``
    renders rectified pinhole pairs; ``"flight"`` renders raw pairs through the true lenses and the CCD image
    formation and rectifies them with the onboard calibration (:mod:`rover_sim.bench.stereo_flight`)."""
    if profile not in PROFILES:
        raise ConfigError("bench stereo", "--profile", f"{profile!r}: use one of {', '.join(PROFILES)}")
    return simulated_pairs(seeds, resolution_px=resolution_px, profile=profile)


def scored_depth(renderer: StereoRenderer, pair: str) -> tuple[np.ndarray, np.ndarray]:
    """(z-depth, scored mask) of ``pair``'s left MJCF camera: terrain or rock (not the rover) within MAX_RANGE_M."""
    depth = renderer.render_depth(f"{pair}_left")
    seg = renderer.render_segmentation(f"{pair}_left")
    m = renderer.sim.model
    valid_ids = seg >= 0
    body_of = np.where(valid_ids, m.geom_bodyid[np.clip(seg, 0, None)], -1)
    ground = valid_ids & (body_of == 0)  # world body: terrain and rocks, not the rover
    return depth, ground & (depth <= MAX_RANGE_M)


def simulated_pairs(
    seeds=(0, 1, 2),
    materials=("sand", "bedrock"),
    pair: str = "hazcam_front",
    resolution_px: int = 256,
    profile: str = "ideal",
) -> list[SimPair]:
    out = []
    for material in materials:
        for seed in seeds:
            recipe = TerrainRecipe(
                size_m=(10.0, 10.0),
                cell_size_m=0.04,
                roughness=RoughnessSpec(rms_m=0.02, correlation_length_m=1.0),
                rocks=RockSpec(cover_fraction=0.06, min_height_m=0.05, max_height_m=0.3),
                material=MaterialSpec(kind=material),
            )
            terrain = synthesize(recipe, seed)
            sim = RoverSim(terrain, texture_rgb=terrain_texture(terrain, 100.0, seed))
            sim.place(0.0, 0.0, float(seed) * 1.3, settle_s=0.5)
            label = f"{material}/{seed}" + ("" if resolution_px == 256 else f" @{resolution_px}")
            if profile == "flight":
                left, right, gt, rig = render_flight_pair(sim, pair, resolution_px, seed, scored_depth)
                out.append(SimPair(left, right, gt, rig, label))
                continue
            with StereoRenderer(sim, RenderConfig(resolution_px=resolution_px, noise=ImageNoise(seed=seed))) as r:
                frame = r.render_pair(pair)
                depth, scored = scored_depth(r, pair)
            gt = np.where(scored, frame.rig.disparity_from_depth(depth), np.nan)
            out.append(SimPair(frame.left, frame.right, gt.astype(np.float32), frame.rig, label))
    return out


def score(disparity: np.ndarray, gt: np.ndarray) -> tuple[float, float]:
    """(density, bad-1px rate) over the scored pixels."""
    scored = np.isfinite(gt)
    has = scored & np.isfinite(disparity)
    density = has.sum() / max(scored.sum(), 1)
    bad = (np.abs(disparity[has] - gt[has]) > 1.0).sum() / max(has.sum(), 1)
    return float(density), float(bad)


def _time_pair_ms(fns: tuple, repeats: int) -> list[float]:
    """Median time (ms) of each function, their runs interleaved (after one warm-up run each)."""
    for fn in fns:
        fn()  # warm-up (workspace allocation)
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(repeats):
        for fn, t in zip(fns, times, strict=True):
            t0 = time.perf_counter()
            fn()
            t.append((time.perf_counter() - t0) * 1e3)
    return [float(np.median(t)) for t in times]


def _rows(pairs: list[SimPair], resolution_px: int, repeats: int) -> list[dict]:
    params = params_for(resolution_px)
    n_disp = params.num_disparities
    rows = []
    for p in pairs:
        ours = compute_disparity(p.left, p.right, params)
        bm = stereobm_baseline(p.left, p.right, n_disp, params.window_px)
        ours_ms, bm_ms = _time_pair_ms(
            (
                lambda p=p: compute_disparity(p.left, p.right, params),
                lambda p=p: stereobm_baseline(p.left, p.right, n_disp, params.window_px),
            ),
            repeats,
        )
        with _opencv_threads(1):  # StereoBM on one thread: what its second thread buys at this size
            bm1_ms = _time_ms(lambda p=p: stereobm_baseline(p.left, p.right, n_disp, params.window_px), repeats)
        # the other SAD engine on the same pair (after the timing): the two must agree bit for bit
        other = compute_disparity(p.left, p.right, params, engine=OTHER_ENGINE[sad_engine()])
        rows.append(
            {
                "pair": p.label,
                "resolution_px": resolution_px,
                "ours": score(ours, p.gt_disparity_px),
                "stereobm": score(bm, p.gt_disparity_px),
                "ours_ms": ours_ms,
                "stereobm_ms": bm_ms,
                "stereobm_1thread_ms": bm1_ms,
                "engines_agree": bool(np.array_equal(ours, other, equal_nan=True)),
            }
        )
    return rows


def _aggregate(rows: list[dict]) -> dict:
    return {
        "ours_ms": float(np.median([r["ours_ms"] for r in rows])),
        "stereobm_ms": float(np.median([r["stereobm_ms"] for r in rows])),
        "stereobm_1thread_ms": float(np.median([r["stereobm_1thread_ms"] for r in rows])),
        "ours_bad1": float(np.mean([r["ours"][1] for r in rows])),
        "stereobm_bad1": float(np.mean([r["stereobm"][1] for r in rows])),
        "ours_density": float(np.mean([r["ours"][0] for r in rows])),
        "stereobm_density": float(np.mean([r["stereobm"][0] for r in rows])),
        "engines_agree": all(r["engines_agree"] for r in rows),
    }


def _print_table(rows: list[dict], agg: dict, label: str) -> None:
    for r in rows:
        print(
            f"| {r['pair']} | {100 * r['ours'][0]:.1f} % | {100 * r['ours'][1]:.2f} % | {100 * r['stereobm'][0]:.1f} % "
            f"| {100 * r['stereobm'][1]:.2f} % | {r['ours_ms']:.1f} | {r['stereobm_ms']:.1f} |"
        )
    print(
        f"| **{label}** | {100 * agg['ours_density']:.1f} % | {100 * agg['ours_bad1']:.2f} % | "
        f"{100 * agg['stereobm_density']:.1f} % | {100 * agg['stereobm_bad1']:.2f} % | {agg['ours_ms']:.1f} | "
        f"{agg['stereobm_ms']:.1f} |"
    )


def bench_stereo(
    json_path: str | None = None,
    plugins: list[str] | None = None,
    profile: str = "flight",
    resolutions_px: tuple[int, ...] = RESOLUTIONS_PX,
    repeats: int = 9,
) -> dict:
    """MER SAD vs StereoBM on the profile's pairs at each resolution (256 px first: the headline keys), then each
    plugin matcher (``plugins``) on the 256 px pairs. The flight profile (default) also runs the ideal pairs, kept
    under ``"ideal"`` beside it (every table says its profile, ideal rows kept)."""
    if not resolutions_px or resolutions_px[0] != 256:
        raise ValueError(f"bench stereo resolutions {resolutions_px}: the first must be 256 (the headline)")
    agg, all_rows, pairs_256 = _bench_profile(profile, resolutions_px, repeats)
    if plugins:
        agg["plugins"] = {name: _plugin_rows(name, pairs_256, agg["stereobm_ms"]) for name in plugins}
    if profile == "flight":
        ideal, ideal_rows, _ = _bench_profile("ideal", resolutions_px, repeats)
        agg["ideal"] = ideal | {"rows": ideal_rows}
    write_json(json_path, agg | {"rows": all_rows})
    return agg


def _bench_profile(profile: str, resolutions_px: tuple[int, ...], repeats: int) -> tuple[dict, list, list]:
    """(aggregate, rows, the 256 px pairs) of one sensor profile, printed as a table."""
    bar = bars.STEREO.max_time_ratio
    print(f"\nsensor profile: {profile}")
    print("| pair | ours density | ours bad-1px | StereoBM density | StereoBM bad-1px | ours ms | StereoBM ms |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    all_rows, per_res, pairs_256 = [], {}, []
    for res in resolutions_px:
        pairs = pairs_for_profile(profile, res)
        pairs_256 = pairs_256 or pairs
        rows = _rows(pairs, res, repeats)
        per_res[res] = _aggregate(rows) | {"threads": threads_used((res, res))}
        _print_table(rows, per_res[res], f"all @{res}")
        all_rows += rows
    agg = dict(per_res[256])
    agg["ratio"] = agg["ours_ms"] / agg["stereobm_ms"]
    for res, a in per_res.items():
        if res == 256:
            continue
        for key, value in a.items():
            agg[f"{key}_{res}"] = value
        agg[f"ratio_{res}"] = a["ours_ms"] / a["stereobm_ms"]
    ratios = {res: (agg["ratio"] if res == 256 else agg[f"ratio_{res}"]) for res in per_res}
    for res, ratio in ratios.items():
        threads = per_res[res]["threads"]
        bm1 = per_res[res]["stereobm_1thread_ms"]
        print(
            f"[{profile}] speed ratio ours/StereoBM @{res} px = {ratio:.2f} (acceptance <= {bar}; SAD engine "
            f"{sad_engine()}; threads: ours {threads['ours']}, StereoBM {threads['stereobm']}; StereoBM on one "
            f"thread {bm1:.1f} ms)"
        )
    agree = [r["engines_agree"] for r in all_rows]
    print(
        f"[{profile}] the {OTHER_ENGINE[sad_engine()]} SAD engine gives the {sad_engine()} engine's disparity bit for "
        f"bit: {sum(agree)} of {len(agree)} pairs"
    )
    agg["profile"] = profile
    agg["sad_engine"] = sad_engine()
    agg["engines_agree"] = all(agree)
    verdict = bars.stereo_verdict(agg)  # the one judge: this summary, the JSON, the JUnit, the exit status
    for c in verdict.checks:
        print(f"[{profile}] {c.name}: {c.cell()}")
    agg["passed"], agg["reasons"] = verdict.passed, verdict.reasons
    return agg, all_rows, pairs_256


def threads_used(shape: tuple[int, int]) -> dict[str, int]:
    """Threads each side may run on for images of ``shape``: ours from :func:`nav.stereo.pipeline_threads`,
    StereoBM's from OpenCV's thread pool (``cv2.getNumThreads()``: StereoBM splits its rows among them)."""
    return {"ours": pipeline_threads(shape), "stereobm": cv2.getNumThreads()}


@contextlib.contextmanager
def _opencv_threads(n: int) -> Iterator[None]:
    """OpenCV's thread count set to ``n`` inside the block, restored after."""
    before = cv2.getNumThreads()
    cv2.setNumThreads(n)
    try:
        yield
    finally:
        cv2.setNumThreads(before)


def _time_ms(fn, repeats: int = 15) -> float:
    return _time_pair_ms((fn,), repeats)[0]


def _plugin_rows(name: str, pairs: list[SimPair], stereobm_ms: float) -> dict:
    """A user's :class:`nav.protocols.StereoMatcher` on the same pairs (guarded: errors name the plugin)."""
    from rover_sim.runtime.plugins import GuardedStereo, instantiate

    matcher = GuardedStereo(instantiate("stereo", name, StereoParams(num_disparities=NUM_DISPARITIES)), name)
    rows = []
    for p in pairs:
        d = matcher.disparity(p.left, p.right, p.rig)
        rows.append(
            {
                "pair": p.label,
                "score": score(d, p.gt_disparity_px),
                "ms": _time_ms(lambda p=p: matcher.disparity(p.left, p.right, p.rig)),
            }
        )
    out = {
        "density": float(np.mean([r["score"][0] for r in rows])),
        "bad1": float(np.mean([r["score"][1] for r in rows])),
        "ms": float(np.median([r["ms"] for r in rows])),
        "rows": rows,
    }
    out["ratio_to_stereobm"] = out["ms"] / stereobm_ms
    print(
        f"| **{name}** | {100 * out['density']:.1f} % | {100 * out['bad1']:.2f} % | | | {out['ms']:.1f} | "
        f"(ratio to StereoBM {out['ratio_to_stereobm']:.2f}) |"
    )
    return out
