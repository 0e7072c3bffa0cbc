"""Rebuild a static body's bounding-volume hierarchy after its geoms moved (streamed terrain, ``sim/stream.py``).

MuJoCo's midphase (``mj_collideTree`` in ``engine_collision_driver.c``) prunes geom pairs with a binary tree of
oriented boxes per body, built once at compile time in the body's inertial frame (``model.bvh_aabb``: centre and
half-sizes; ``bvh_child``: child node indices relative to the body's root, -1 for none; ``bvh_nodeid``: the geom of
a leaf). The streamed heightfield window and its rock pool are geoms of the world body moved in place, so that tree
goes stale when the window re-centres. :func:`rebuild_body_bvh` rebuilds it with the compiler's rule (split the
geoms at the median of their box centres along the widest axis) over the same leaves; a binary tree of ``n``
single-geom leaves always has ``2 n - 1`` nodes, so it fits the compiled arrays exactly and the midphase stays valid.
The leaf test itself reads the live ``geom_xpos`` and ``geom_aabb``; only the inner boxes needed refreshing.
"""

from __future__ import annotations

import mujoco
import numpy as np


def world_boxes(model: mujoco.MjModel, geoms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) centres and half-sizes of axis-aligned boxes bounding static ``geoms`` in the world frame (from
    ``geom_pos``, ``geom_quat`` and the local ``geom_aabb``; world-body geoms only)."""
    local = model.geom_aabb[geoms]
    centres, halves = np.empty((len(geoms), 3)), np.empty((len(geoms), 3))
    R = np.empty(9)
    for k, g in enumerate(geoms):
        mujoco.mju_quat2Mat(R, model.geom_quat[g])
        M = R.reshape(3, 3)
        centres[k] = model.geom_pos[g] + M @ local[k, :3]
        halves[k] = np.abs(M) @ local[k, 3:]
    return centres, halves


def rebuild_body_bvh(model: mujoco.MjModel, body_id: int = 0) -> None:
    """Rebuild ``body_id``'s tree in ``model`` (in place) from its geoms' current poses and sizes. The body must be
    the world body (its inertial frame is the world frame); the set of leaves is the compiled one."""
    if body_id != 0:
        raise ValueError(f"rebuild_body_bvh handles the static world body only, not body {body_id}")
    adr, num = int(model.body_bvhadr[body_id]), int(model.body_bvhnum[body_id])
    if adr < 0 or num == 0:
        return
    nodeid = model.bvh_nodeid[adr : adr + num]
    geoms = np.sort(nodeid[nodeid >= 0])
    if num != 2 * len(geoms) - 1:
        raise ValueError(f"body {body_id}'s tree has {num} nodes for {len(geoms)} leaves; expected one geom a leaf")
    centres, halves = world_boxes(model, geoms)
    lo, hi = centres - halves, centres + halves
    aabb = np.empty((num, 6))
    child = np.full((num, 2), -1, dtype=np.int32)
    ids = np.full(num, -1, dtype=np.int32)
    depth = np.zeros(num, dtype=np.int32)
    next_free = [0]

    def build(members: np.ndarray, level: int) -> int:
        node = next_free[0]
        next_free[0] += 1
        box_lo, box_hi = lo[members].min(axis=0), hi[members].max(axis=0)
        aabb[node, :3], aabb[node, 3:] = 0.5 * (box_lo + box_hi), 0.5 * (box_hi - box_lo)
        depth[node] = level
        if len(members) == 1:
            ids[node] = geoms[members[0]]
            return node
        c = centres[members]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = members[np.argsort(c[:, axis], kind="stable")]
        half = len(order) // 2
        child[node, 0] = build(order[:half], level + 1)
        child[node, 1] = build(order[half:], level + 1)
        return node

    build(np.arange(len(geoms)), 0)
    model.bvh_aabb[adr : adr + num] = aabb
    model.bvh_child[adr : adr + num] = child
    model.bvh_nodeid[adr : adr + num] = ids
    model.bvh_depth[adr : adr + num] = depth
