"""A navcam panorama at a stop, as a global localiser receives it: rectified pairs with their calibrated rigs, and
the onboard attitude (IMU roll and pitch after standing, the onboard yaw).

The pairs come from the rock survey's panorama acquisition (:meth:`rover_sim.apps.survey.RockSiteSurvey.
panorama_pair`: the scenario's sensor profile, true lenses and CCD chain, rectified on board with the calibrated
models at the commanded pointing), so a global fix and a rock site see the same images.
"""

from __future__ import annotations

import math

import numpy as np

from nav.geometry import quat_wxyz_to_R
from nav.globalloc import PanoramaView
from rover_sim.apps.survey import MAST_SETTLE_S, REST_BEFORE_PANORAMA_S, RockSiteSurvey

PAN_STEP_DEG = 45.0  # eight pairs cover 360 deg with the navcam's 45 deg field of view
ELEVATION_DEG = -12.0  # the frames span ~2.5 m from the mast to the horizon


def pans_deg(step_deg: float = PAN_STEP_DEG) -> list[float]:
    n = max(1, int(round(360.0 / step_deg)))
    return [-180.0 + (360.0 / n) * (k + 0.5) for k in range(n)]


MAX_PARK_SLOPE_DEG = 12.0  # the rover parks on gentle ground (a ripple's lee face would not hold it)


def gentle_spot(terrain: object, x_m: float, y_m: float, max_slope_deg: float = MAX_PARK_SLOPE_DEG,
                search_m: float = 2.5) -> tuple[float, float]:  # fmt: skip
    """The point nearest ``(x_m, y_m)`` (within ``search_m``, 0.25 m steps) where the ground under the rover's
    footprint is gentler than ``max_slope_deg``; the point itself if none is."""
    ring = np.linspace(0.0, 2.0 * math.pi, 12, endpoint=False)
    offsets = [(0.0, 0.0)] + [(r * math.cos(a), r * math.sin(a)) for r in np.arange(0.25, search_m + 1e-9, 0.25)
                              for a in ring]  # fmt: skip
    foot = np.array([[0.0, 0.0], [0.6, 0.6], [0.6, -0.6], [-0.6, 0.6], [-0.6, -0.6]])
    for dx, dy in offsets:
        px, py = x_m + dx + foot[:, 0], y_m + dy + foot[:, 1]
        if float(np.max(terrain.slope_deg_at(px, py))) < max_slope_deg:  # type: ignore[attr-defined]
            return x_m + dx, y_m + dy
    return x_m, y_m


def place_rover(survey: RockSiteSurvey, x_m: float, y_m: float, yaw_rad: float) -> None:
    """Put the rover at a stop (the bench's stops are independent: no drive between them) and let it settle. The
    simulation clock keeps running forward (the sensors' samples stay in time order)."""
    sim = survey.mission.sim
    t_s = sim.time_s
    sim.place(x_m, y_m, yaw_rad, settle_s=0.0)
    sim.data.time = t_s
    survey.mission.stand(1.5)


def take_panorama(survey: RockSiteSurvey, elevation_deg: float = ELEVATION_DEG) -> list[PanoramaView]:
    """Stand (suspension settles, the dead reckoner re-levels), then a pair at every pan; mast back after."""
    m = survey.mission
    m.stand(REST_BEFORE_PANORAMA_S)
    views = []
    for pan in pans_deg():
        m.point_mast(pan, elevation_deg, settle_s=MAST_SETTLE_S)
        pair = survey.panorama_pair()
        views.append(PanoramaView(pair.left_u8, pair.right_u8, pair.rig))
    m.point_mast(survey.sc.nav.mast_pan_deg, survey.sc.nav.mast_tilt_deg)
    return views


def onboard_attitude(survey: RockSiteSurvey, yaw_rad: float) -> np.ndarray:
    """The onboard attitude estimate (roll, pitch from the dead reckoner at rest) turned to heading ``yaw_rad``."""
    R = np.asarray(survey.mission.onboard.pose.R_world_rover, dtype=float)
    own = math.atan2(R[1, 0], R[0, 0])
    c, s = math.cos(yaw_rad - own), math.sin(yaw_rad - own)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ R


def true_pose_xy_yaw(survey: RockSiteSurvey) -> np.ndarray:
    """Ground truth (evaluation only): x, y, yaw of the rover."""
    sim = survey.mission.sim
    R = quat_wxyz_to_R(sim.quat_wxyz())
    p = sim.position_m()
    return np.array([p[0], p[1], math.atan2(R[1, 0], R[0, 0])])
