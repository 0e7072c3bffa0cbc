"""The rover's shape as flight software would hold it (design data): oriented boxes from the MJCF at its home pose.

:func:`rover_shape` compiles ``models/mer/rover.xml`` once, poses it at the home configuration (mast at pan 0,
tilt 0; suspension and steering at zero) and returns every visual geom's bounding box as a
:class:`nav.vo.shadow.RoverShape`: body geoms in the rover frame, mast-head geoms in the navcam-left camera frame
(so the onboard side places them with the calibrated navcam model at the commanded pointing). Nothing here reads a
running simulation: the onboard stack receives this once, at construction.
"""

from __future__ import annotations

from functools import lru_cache

import mujoco
import numpy as np

from nav.vo.shadow import RoverShape
from rover_sim.render.cameras import ROVER_BODY, camera_world_pose, rover_world_pose
from rover_sim.resources import models_dir

VISUAL_GROUP = 2  # rover.xml: visual geoms (drawn, cast shadows); group 3 holds the collision proxies
HEAD_BODY = "mast_head"


def _geom_box(model: mujoco.MjModel, data: mujoco.MjData, g: int) -> tuple[np.ndarray, np.ndarray]:
    """World pose (4x4) and half-sizes of geom ``g``'s bounding box (MuJoCo's local AABB)."""
    aabb = model.geom_aabb[g]  # centre (3) then half-sizes (3), geom frame
    T = np.eye(4)
    T[:3, :3] = data.geom_xmat[g].reshape(3, 3)
    T[:3, 3] = data.geom_xpos[g] + T[:3, :3] @ aabb[:3]
    return T, np.asarray(aabb[3:], dtype=float).copy()


def _under(model: mujoco.MjModel, body: int, ancestor: int) -> bool:
    while body > 0:
        if body == ancestor:
            return True
        body = int(model.body_parentid[body])
    return False


@lru_cache(maxsize=1)
def rover_shape() -> RoverShape:
    """The MER model's visual geoms as boxes (see the module docstring); computed once per process."""
    model = mujoco.MjModel.from_xml_path(str(models_dir() / "mer" / "rover.xml"))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    T_rover_world = np.linalg.inv(rover_world_pose(model, data))
    T_cam_world = np.linalg.inv(camera_world_pose(model, data, "navcam_left"))
    head = model.body(HEAD_BODY).id
    body, body_half, hb, hb_half = [], [], [], []
    for g in range(model.ngeom):
        if model.geom_group[g] != VISUAL_GROUP or model.geom_rgba[g, 3] <= 0:
            continue
        T, h = _geom_box(model, data, g)
        if _under(model, int(model.geom_bodyid[g]), head):
            hb.append(T_cam_world @ T)
            hb_half.append(h)
        else:
            body.append(T_rover_world @ T)
            body_half.append(h)
    wheels = [model.geom(f"wheel_{w}").id for w in ("lf", "lm", "lr", "rf", "rm", "rr")]
    bottoms = [(T_rover_world @ np.append(data.geom_xpos[w], 1.0))[2] - model.geom_size[w, 0] for w in wheels]
    assert model.body(ROVER_BODY).id > 0
    return RoverShape(
        boxes=np.array(body), half_m=np.array(body_half), head_boxes=np.array(hb), head_half_m=np.array(hb_half),
        ground_z_m=float(np.mean(bottoms)),
    )  # fmt: skip
