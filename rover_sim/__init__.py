"""rover-sim: MuJoCo MER-class rover, wheel-soil physics, sensors, rendering, runner, logging and benchmarks.

``MUJOCO_GL`` defaults to ``egl`` here, before anything imports mujoco, so offscreen rendering works headless.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

__version__ = "0.1.0"
