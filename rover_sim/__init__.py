"""rover-sim: MuJoCo MER-class rover, wheel-soil physics, sensors, rendering, runner, logging and benchmarks.

``MUJOCO_GL`` defaults to ``egl`` here, before anything imports mujoco, so offscreen rendering works headless.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

__version__ = "0.1.0"

# Gymnasium environments rover_sim/MER-v0 and rover_sim/MERGoal-v0 (lazy: registers an entry-point string;
# neither mujoco nor the simulator is imported until an environment is made).
try:
    import gymnasium as _gymnasium  # noqa: F401
except ModuleNotFoundError:  # pragma: no cover - gymnasium is a dependency; without it there is simply no env
    pass
else:
    from rover_sim.env import register_envs as _register_envs

    _register_envs()
