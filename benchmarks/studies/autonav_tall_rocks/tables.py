# ruff: noqa: E501, E731, B023, B905
"""The tables of docs/navigation/autonav-tall-rocks.md from the looks of sample_looks.py: single-look GESTALT maps
(points placed with the true pose) with and without the apex correction; per rock in view its true height and shape,
the mapped top, the step and goodness over it; and the rock-free cells.

    python tables.py 'DIR/s_*.npz'
"""

import glob
import math
import sys

import numpy as np

from nav.gestalt import GestaltParams, GoodnessMap
from terrains.terrain import Rock


def looks(paths):
    for p in paths:
        z = np.load(p)
        rocks = [Rock(x, y, zb, str(s), L, W, h, yaw) for (x, y, zb, L, W, h, yaw), s in zip(z["rocks"], z["shapes"])]
        R = z["rocks"]
        off = np.concatenate([[0], np.cumsum(z["npts"])])
        for i in range(len(z["T"])):
            yield p, rocks, R, z["T"][i], z["pts"][off[i] : off[i + 1]].astype(float)


def evaluate(paths, params, pts_fn=None):
    rock_rows, free = [], []
    for p, rocks, R, T, pr in looks(paths):
        if pts_fn is not None:
            pr = pts_fn(p, pr)
        pw = pr @ T[:3, :3].T + T[:3, 3]
        rx, ry = T[0, 3], T[1, 3]
        yaw = math.atan2(T[1, 0], T[0, 0])
        gm = GoodnessMap(params)
        gm.update(pw, np.array([rx, ry]))
        win = gm.evaluate(np.array([rx, ry]))
        cen = win.cell_centres_xy()
        rad = 0.5 * np.maximum(R[:, 3], R[:, 4])
        for k, r in enumerate(rocks):
            if r.height_m < 0.08:
                continue
            dx, dy = r.x_m - rx, r.y_m - ry
            rng = math.hypot(dx, dy)
            fwd = math.cos(yaw) * dx + math.sin(yaw) * dy
            lat = -math.sin(yaw) * dx + math.cos(yaw) * dy
            if not (0.9 <= rng <= 3.3) or fwd < 0.8 or abs(lat) > 0.9 * fwd:
                continue
            top = r.top_z_at(pw[:, 0], pw[:, 1])
            ins = np.isfinite(top)
            n = int(ins.sum())
            if n < 5:
                continue
            zrel = np.sort(pw[ins, 2] - r.z_base_m)
            kk = min(int(0.1 * n), (n - 1) // 2)
            near = np.hypot(cen[..., 0] - r.x_m, cen[..., 1] - r.y_m) <= rad[k]
            g = win.goodness[near]
            st = win.step_m[near]
            ring = np.hypot(cen[..., 0] - r.x_m, cen[..., 1] - r.y_m) <= rad[k] + 0.25
            gr = win.goodness[ring]
            gr = gr[np.isfinite(gr)]
            cover = float(np.mean(gr <= 0.0)) if gr.size else np.nan
            rock_rows.append(
                dict(
                    k=k,
                    shape=r.shape,
                    h=r.height_m,
                    rng=rng,
                    n=n,
                    zmax=zrel[-1],
                    ztrim=zrel[n - 1 - kk],
                    gmin=np.nanmin(g) if np.isfinite(g).any() else np.nan,
                    step=np.nanmax(st) if np.isfinite(st).any() else np.nan,
                    cover=cover,
                )
            )
        # rock-free cells: known, more than (radius + 0.8 m) from every rock >= 8 cm
        d = np.hypot(cen[..., 0, None] - R[None, None, :, 0], cen[..., 1, None] - R[None, None, :, 1]) - rad - 0.8
        clear = (d > 0).all(axis=-1) & np.isfinite(win.goodness)
        cr = np.hypot(cen[..., 0] - rx, cen[..., 1] - ry)
        for c_rng, g in zip(cr[clear], win.goodness[clear]):
            free.append((c_rng, g))
    return rock_rows, np.array(free)


paths = sorted(glob.glob(sys.argv[1]))
old, free_old = evaluate(paths, GestaltParams(apex_reach_rad=None))
new, free_new = evaluate(paths, GestaltParams())
print(
    f"fields {[p.split('_')[-1][:-4] for p in paths]}; looks {sum(len(np.load(p)['T']) for p in paths)}; sightings {len(old)}"
)
print("\n### under-read: rocks >= 18 cm, 0.9-3.3 m")
print(
    "| shape | range (m) | sightings | mapped top / true height: median [p10, p90] | highest point / true height: median | under-read (cm): median [p90] |"
)
print("|---|---|---:|---:|---:|---:|")
shapes = ("cone", "tetrahedron", "hemispheroid", "semi_ellipsoid")
for shape in shapes:
    for lo, hi in ((0.9, 1.8), (1.8, 2.6), (2.6, 3.3)):
        rs = [r for r in old if r["shape"] == shape and r["h"] >= 0.18 and lo <= r["rng"] < hi]
        if not rs:
            continue
        ratio = np.array([r["ztrim"] / r["h"] for r in rs])
        mx = np.array([r["zmax"] / r["h"] for r in rs])
        under = 100 * np.array([r["h"] - r["ztrim"] for r in rs])
        print(
            f"| {shape} | {lo}-{hi} | {len(rs)} | {np.median(ratio):.2f} [{np.percentile(ratio, 10):.2f}, {np.percentile(ratio, 90):.2f}] | {np.median(mx):.2f} | {np.median(under):.1f} [{np.percentile(under, 90):.1f}] |"
        )
print("\n### rocks >= 25 cm: step seen (old -> new) and impassable")
print(
    "| shape | sightings 0.9-2.6 m | step (m) median old | new | impassable old | new | cells within r+25 cm impassable old | new |"
)
print("|---|---:|---:|---:|---:|---:|---:|---:|")
for shape in shapes + ("all",):
    sel = lambda rr: [
        r for r in rr if (shape == "all" or r["shape"] == shape) and r["h"] >= 0.25 and 0.9 <= r["rng"] < 2.6
    ]
    o, n = sel(old), sel(new)
    if not o:
        continue
    f = lambda rs: np.mean([r["gmin"] <= 0 for r in rs])
    print(
        f"| {shape} | {len(o)} | {np.nanmedian([r['step'] for r in o]):.2f} | {np.nanmedian([r['step'] for r in n]):.2f} | {f(o):.2f} | {f(n):.2f} | {np.nanmean([r['cover'] for r in o]):.2f} | {np.nanmean([r['cover'] for r in n]):.2f} |"
    )
print("\n### false hazards")
print(
    "| range (m) | rocks 8-15 cm impassable old | new | (sightings) | rock-free cells impassable old | new | (cells) |"
)
print("|---|---:|---:|---:|---:|---:|---:|")
for lo, hi in ((0.9, 1.8), (1.8, 2.6), (2.6, 3.3)):
    so = [r for r in old if 0.08 <= r["h"] < 0.15 and lo <= r["rng"] < hi]
    sn = [r for r in new if 0.08 <= r["h"] < 0.15 and lo <= r["rng"] < hi]
    fo = free_old[(free_old[:, 0] >= lo) & (free_old[:, 0] < hi)]
    fn = free_new[(free_new[:, 0] >= lo) & (free_new[:, 0] < hi)]
    print(
        f"| {lo}-{hi} | {np.mean([r['gmin'] <= 0 for r in so]):.2f} | {np.mean([r['gmin'] <= 0 for r in sn]):.2f} | {len(so)} | {np.mean(fo[:, 1] <= 0):.3f} | {np.mean(fn[:, 1] <= 0):.3f} | {len(fo)} |"
    )
