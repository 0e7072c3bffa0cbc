"""The terrain types of ``bench globalloc``: four sites a global localiser meets, as scenarios of a seed.

Each site is a 72 m square whole-site terrain at 10 cm cells (rocks are meshes, so the ground is smooth at 10 cm)
with the stops drawn near its centre (``STOP_HALF_M``); the orbital products cover the whole site. Sun at the stops:
10:30 local time at the equator at Ls 0 (the orbiter's products are at 15:00, ``[orbital]``).

* ``rocky_plains``: Gusev-like plains, Golombek-Rapp k = 0.07, rocks 0.12-0.8 m, all four rock models;
* ``crater_rim``: the rim of a 50 m degraded crater (depth/diameter 0.15) runs through the stops, sparse rocks;
* ``dune_field``: sand ripples 0.7 m crest-to-trough, 6 m apart, few rocks: repetitive along the crests;
* ``featureless_plain``: Meridiani-like fine soil, no rocks, flat: nothing to see from orbit at 25 cm.
"""

from __future__ import annotations

import math

import numpy as np

SITE_M = 72.0
STOP_HALF_M = 6.0  # stops within +- this of the site centre
STOP_CLEAR_M = 1.8  # rocks are kept this far from every stop (the rover stands on open ground)
TERRAINS = ("rocky_plains", "crater_rim", "dune_field", "featureless_plain")


def stops_xy_yaw(seed: int, n: int) -> np.ndarray:
    """(n, 3) stop positions and headings of a seed (deterministic)."""
    rng = np.random.default_rng([int(seed), 0x6C0C])
    out = np.empty((n, 3))
    for k in range(n):
        while True:
            xy = rng.uniform(-STOP_HALF_M, STOP_HALF_M, 2)
            if k == 0 or np.min(np.hypot(*(out[:k, :2] - xy).T)) > 3.0:
                break
        out[k] = (*xy, rng.uniform(-math.pi, math.pi))
    return out


def site_scenario(terrain: str, seed: int, stops: np.ndarray) -> dict:
    """The scenario (as a dict for ``scenario_from_dict``) of ``terrain`` with ``seed``."""
    clear = [[float(x), float(y), STOP_CLEAR_M] for x, y, _ in stops]
    rocks = {"cover_fraction": 0.0, "min_height_m": 0.12, "max_height_m": 0.8, "exclusion_zones": clear}
    t: dict = {"size_m": [SITE_M, SITE_M], "cell_size_m": 0.1, "material": {"kind": "sand"},
               "roughness": {"rms_m": 0.02, "correlation_length_m": 2.0}}  # fmt: skip
    appearance: dict = {"texture_px_per_m": 60.0}
    if terrain == "rocky_plains":
        t["slope"] = {"slope_deg": 1.0, "azimuth_deg": 45.0}
        rocks["cover_fraction"] = 0.07
    elif terrain == "crater_rim":
        t["craters"] = [{"center_xy_m": [25.0, 0.0], "diameter_m": 50.0, "depth_to_diameter": 0.15,
                         "rim_height_frac": 0.036, "rim_width_frac": 0.15}]  # fmt: skip
        t["material"] = {"kind": "sand", "outcrop_slope_deg": 25.0}
        rocks["cover_fraction"] = 0.03
    elif terrain == "dune_field":
        t["ripples"] = {"amplitude_m": 0.35, "wavelength_m": 6.0, "azimuth_deg": 30.0, "sharpness": 0.6,
                        "sinuosity": 0.1}  # fmt: skip
        t["roughness"] = {"rms_m": 0.01, "correlation_length_m": 1.0}
        rocks["cover_fraction"] = 0.005
    elif terrain == "featureless_plain":
        t["roughness"] = {"rms_m": 0.005, "correlation_length_m": 2.0}
        appearance["fine_soil"] = True
    else:
        raise ValueError(f"unknown terrain {terrain!r}; one of {', '.join(TERRAINS)}")
    t["rocks"] = rocks
    x0, y0, yaw0 = stops[0]
    return {
        "name": f"globalloc_{terrain}",
        "description": f"bench globalloc site: {terrain}",
        "seed": int(seed),
        "terrain": t,
        "appearance": appearance,
        "sun": {"local_solar_time_h": 10.5},
        "start": {"x_m": float(x0), "y_m": float(y0), "yaw_deg": math.degrees(yaw0)},
        "nav": {"vo": False, "camera": "navcam"},
        "commands": [{"type": "drive", "distance_m": 0.1}],
    }
