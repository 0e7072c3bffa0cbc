"""All rover-sim exceptions, each saying what went wrong and how to fix it (Gymnasium ``error.py`` style)."""

from __future__ import annotations


class RoverSimError(Exception):
    """Base class of every error rover-sim raises on purpose."""


class PhysicsDiverged(RoverSimError):
    """The simulation produced NaN/Inf or MuJoCo instability warnings; the run stops and keeps what it recorded."""

    def __init__(self, time_s: float, cause: str) -> None:
        self.time_s = time_s
        self.cause = cause
        super().__init__(
            f"physics diverged at t={time_s:.3f} s: {cause}. Try a smaller timestep (--set physics.timestep_s=...) "
            "or check the terrain for extreme slopes/rock overlaps."
        )


class ConfigError(RoverSimError):
    """A scenario or config file is invalid: names the file, the field and the allowed range."""

    def __init__(self, path: str, field: str, message: str) -> None:
        self.path, self.field = path, field
        super().__init__(f"{path}: field '{field}': {message}")


class UnknownScenario(ConfigError):
    """No scenario of that name (or no such file): names the closest scenario names and the catalogue."""

    def __init__(self, name: str, known: list[str], is_name: bool = True) -> None:
        import difflib

        close = difflib.get_close_matches(name, known, n=3, cutoff=0.6) if is_name else []
        close += [k for k in known if is_name and name.lower() in k and k not in close][: 3 - len(close)]
        hint = f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else ""
        what = f"no scenario named {name!r}" if is_name else f"{name}: no such scenario file"
        RoverSimError.__init__(self, f"{what}{hint}; known scenarios: {', '.join(known)}")
        self.path, self.field = name, "(file)"


class RenderingUnavailable(RoverSimError):
    """No offscreen OpenGL (EGL) is available."""

    def __init__(self, detail: str) -> None:
        super().__init__(
            f"offscreen rendering needs EGL ({detail}). On Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri"
        )


class DaskUnavailable(RoverSimError):
    """``--scheduler`` was given but dask.distributed is not installed."""

    def __init__(self, detail: str) -> None:
        super().__init__(
            f"--scheduler needs dask.distributed ({detail}). Install the extra: pip install 'rover-sim[dask]'"
        )


class SchedulerUnreachable(RoverSimError):
    """No Dask scheduler answered at the given address."""

    def __init__(self, address: str, detail: str) -> None:
        super().__init__(
            f"no Dask scheduler at {address} ({detail}). Start one with `dask scheduler` and workers with "
            f"`dask worker {address}` on machines that have rover-sim installed"
        )


class PluginError(RoverSimError):
    """A user-supplied stereo matcher, visual odometer or planner could not be loaded, raised, or answered outside
    its protocol (``nav.protocols``); names the plugin, the method or field, and what was wrong."""

    def __init__(self, plugin: str, where: str, problem: str) -> None:
        self.plugin, self.where, self.problem = plugin, where, problem
        super().__init__(f"plugin {plugin}: {where}: {problem}")


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived (a CI timeout, ``kill``, a batch scheduler): handled like Ctrl-C, so the run stops cleanly
    and keeps what it recorded (see :mod:`rover_sim.interrupts`); the CLI exits 143 instead of 130."""
