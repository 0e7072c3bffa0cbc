"""The offscreen OpenGL helpers: the EGL availability check and drawing at several sizes in one context."""

from __future__ import annotations

import os
from functools import cache

import mujoco

from rover_sim.errors import RenderingUnavailable


@cache
def check_gl() -> None:
    """Fail early, with the install hint, if no offscreen OpenGL (EGL) context can be made in this process."""
    backend = os.environ.get("MUJOCO_GL", "")
    module = getattr(getattr(mujoco, "GLContext", None), "__module__", "") or "no GL backend"
    if backend in ("egl", "osmesa") and not module.startswith(f"mujoco.{backend}"):
        raise RenderingUnavailable(
            f"mujoco was imported before MUJOCO_GL={backend} took effect and uses {module}; import rover_sim "
            "before mujoco, or export MUJOCO_GL=egl"
        )
    try:
        ctx = mujoco.GLContext(16, 16)
        try:
            ctx.make_current()
            con = mujoco.MjrContext(mujoco.MjModel.from_xml_string("<mujoco/>"), mujoco.mjtFontScale.mjFONTSCALE_100)
            con.free()
        finally:
            ctx.free()
    except Exception as exc:  # noqa: BLE001 - any backend failure means "no GL here"; re-raised with the fix
        raise RenderingUnavailable(f"{type(exc).__name__}: {exc}") from exc


def set_viewport(renderer: mujoco.Renderer, px: int) -> None:
    """Make ``renderer`` draw and read back the ``px`` x ``px`` corner of its offscreen framebuffer.

    :class:`mujoco.Renderer` keeps its output size in ``_width`` / ``_height`` / ``_rect`` (mujoco 3.x; the render
    tests fail if that changes); ``mjr_render`` and ``mjr_readPixels`` use ``_rect``, the image shape the sizes."""
    renderer._width = renderer._height = px
    renderer._rect.width = renderer._rect.height = px
