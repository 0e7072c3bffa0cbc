"""Loading the swappable parts of the onboard stack and guarding every call into them.

An implementation is named ``"builtin"`` (MER SAD stereo, MER VO, GESTALT), by import path
``"package.module:Attribute"`` (a class or factory called with no arguments, or with the part's parameters if it
accepts a ``params`` keyword), or by the name of an entry point in the group ``rover_sim.plugins`` that an
installed package registers::

    [project.entry-points."rover_sim.plugins"]
    my_vo = "mypkg.vo:MyVO"

Every call goes through a guard that turns an exception or a result outside the protocol (``nav.protocols``) into
:class:`rover_sim.errors.PluginError` naming the plugin and the field; the pipeline then stops the run cleanly.
"""

from __future__ import annotations

import importlib
import inspect
import os
import sys
from importlib.metadata import entry_points
from typing import Any

import numpy as np

from nav.gestalt import GestaltPlanner
from nav.protocols import (
    GlobalLocalizer,
    Planner,
    PluginContractError,
    StereoMatcher,
    VisualOdometer,
    check_decision,
    check_disparity,
    check_globalloc_result,
    check_vo_result,
)
from nav.stereo import SadStereo
from nav.vo import VisualOdometry
from rover_sim.errors import PluginError
from rover_sim.scenario.nav_spec import BUILTIN, PlannerSpec, StereoSpec, VoSpec

ENTRY_POINT_GROUP = "rover_sim.plugins"
PROTOCOLS: dict[str, type] = {
    "vo": VisualOdometer,
    "stereo": StereoMatcher,
    "planner": Planner,
    "globalloc": GlobalLocalizer,
}


def resolve(spec: str) -> Any:
    """The object an implementation name points at (not yet instantiated)."""
    if ":" in spec:
        module_name, _, attr = spec.partition(":")
        cwd = os.getcwd()
        if cwd not in sys.path:  # like `python -m`: modules in the current directory are importable
            sys.path.append(cwd)
        try:
            module = importlib.import_module(module_name)
        except ImportError as err:
            raise PluginError(spec, "import", f"cannot import module '{module_name}' ({err})") from None
        try:
            obj: Any = module
            for part in attr.split("."):
                obj = getattr(obj, part)
            return obj
        except AttributeError:
            raise PluginError(spec, "import", f"module '{module_name}' has no attribute '{attr}'") from None
    found = [ep for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name == spec]
    if not found:
        known = ", ".join(sorted(ep.name for ep in entry_points(group=ENTRY_POINT_GROUP))) or "none installed"
        raise PluginError(
            spec,
            "name",
            f"not 'builtin', not an import path 'module:Class', and no entry point of that name in "
            f"'{ENTRY_POINT_GROUP}' (installed: {known})",
        )
    try:
        return found[0].load()
    except Exception as err:  # noqa: BLE001 - a broken third-party package: report it, do not crash
        raise PluginError(spec, "import", f"entry point failed to load: {type(err).__name__}: {err}") from None


def instantiate(kind: str, spec: str, params: object | None = None) -> Any:
    """Build the ``kind`` ("vo", "stereo", "planner") implementation ``spec`` and check it has the protocol."""
    factory = resolve(spec)
    try:
        accepts_params = params is not None and "params" in inspect.signature(factory).parameters
    except (TypeError, ValueError):
        accepts_params = False
    try:
        obj = factory(params=params) if accepts_params else (factory() if callable(factory) else factory)
    except PluginError:
        raise
    except Exception as err:  # noqa: BLE001 - user code
        raise PluginError(spec, "constructor", f"{type(err).__name__}: {err}") from None
    protocol = PROTOCOLS[kind]
    if not isinstance(obj, protocol):
        methods = ("reset", "step", "disparity", "arcs", "localize")
        missing = [m for m in methods if hasattr(protocol, m) and not hasattr(obj, m)]
        raise PluginError(
            spec,
            "protocol",
            f"{type(obj).__name__} does not implement nav.protocols.{protocol.__name__} "
            f"(missing: {', '.join(missing) or 'a method'})",
        )
    return obj


class GuardedVO:
    """A :class:`nav.protocols.VisualOdometer` whose every answer is checked (see the module docstring)."""

    def __init__(self, impl: VisualOdometer, name: str) -> None:
        self.impl, self.name = impl, name
        try:
            params = inspect.signature(impl.step).parameters
        except (TypeError, ValueError):
            params = {}
        # the shadow mask is offered only to a plugin whose step() declares it (nav.protocols.VisualOdometer)
        self.takes_mask = "feature_mask" in params or any(p.kind is p.VAR_KEYWORD for p in params.values())

    def reset(self) -> None:
        try:
            self.impl.reset()
        except Exception as err:  # noqa: BLE001 - user code
            raise PluginError(self.name, "reset()", f"raised {type(err).__name__}: {err}") from None

    def step(self, left_u8: np.ndarray, right_u8: np.ndarray, rig, predicted_motion_rover=None, R_world_rover=None,  # noqa: ANN001, ANN201
             **kw):  # fmt: skip
        extra = {"feature_mask": kw["feature_mask"]} if self.takes_mask and "feature_mask" in kw else {}
        try:
            res = self.impl.step(left_u8, right_u8, rig, predicted_motion_rover, R_world_rover=R_world_rover, **extra)
        except Exception as err:  # noqa: BLE001 - user code
            raise PluginError(self.name, "step()", f"raised {type(err).__name__}: {err}") from None
        try:
            check_vo_result(res)
        except PluginContractError as err:
            raise PluginError(self.name, f"step() result field '{err.field}'", err.problem) from None
        return res


class GuardedStereo:
    def __init__(self, impl: StereoMatcher, name: str) -> None:
        self.impl, self.name = impl, name

    def disparity(self, left_u8: np.ndarray, right_u8: np.ndarray, rig) -> np.ndarray:  # noqa: ANN001
        try:
            d = self.impl.disparity(left_u8, right_u8, rig)
        except Exception as err:  # noqa: BLE001 - user code
            raise PluginError(self.name, "disparity()", f"raised {type(err).__name__}: {err}") from None
        try:
            return check_disparity(d, left_u8.shape)
        except PluginContractError as err:
            raise PluginError(self.name, f"disparity() result '{err.field}'", err.problem) from None


class GuardedPlanner:
    def __init__(self, impl: Planner, name: str) -> None:
        self.impl, self.name = impl, name

    @property
    def arcs(self) -> list:
        return list(self.impl.arcs)

    def step(self, points_world: np.ndarray, pose_xy_yaw: np.ndarray, goal_xy: np.ndarray):  # noqa: ANN201
        try:
            decision = self.impl.step(points_world, pose_xy_yaw, goal_xy)
        except Exception as err:  # noqa: BLE001 - user code
            raise PluginError(self.name, "step()", f"raised {type(err).__name__}: {err}") from None
        try:
            check_decision(decision, len(self.impl.arcs))
        except PluginContractError as err:
            raise PluginError(self.name, f"step() decision field '{err.field}'", err.problem) from None
        return decision


def make_vo(spec: VoSpec) -> VisualOdometer | None:
    """The configured visual odometer (None when VO is off)."""
    if not spec.enabled:
        return None
    if spec.impl == BUILTIN:
        return VisualOdometry(spec.params, spec.sanity)
    return GuardedVO(instantiate("vo", spec.impl, spec.params), spec.impl)


def make_stereo(spec: StereoSpec) -> StereoMatcher:
    if spec.impl == BUILTIN:
        return SadStereo(spec.params)
    return GuardedStereo(instantiate("stereo", spec.impl, spec.params), spec.impl)


def make_planner(spec: PlannerSpec) -> Planner:
    if spec.impl == BUILTIN:
        return GestaltPlanner(spec.params)
    return GuardedPlanner(instantiate("planner", spec.impl, spec.params), spec.impl)


class GuardedGlobalLocalizer:
    """A :class:`nav.protocols.GlobalLocalizer` whose every answer is checked."""

    def __init__(self, impl: GlobalLocalizer, name: str) -> None:
        self.impl, self.name = impl, name

    def localize(self, views, R_world_rover, prior_xy_yaw, prior_covariance, orbital):  # noqa: ANN001, ANN201
        try:
            res = self.impl.localize(views, R_world_rover, prior_xy_yaw, prior_covariance, orbital)
        except Exception as err:  # noqa: BLE001 - user code
            raise PluginError(self.name, "localize()", f"raised {type(err).__name__}: {err}") from None
        try:
            check_globalloc_result(res)
        except PluginContractError as err:
            raise PluginError(self.name, f"localize() result field '{err.field}'", err.problem) from None
        return res


def make_global_localizer(spec: str) -> GlobalLocalizer:
    """The built-in orbital localiser (``"builtin"``) or a plugin, guarded."""
    if spec == BUILTIN:
        from nav.globalloc import OrbitalLocalizer

        return OrbitalLocalizer()
    return GuardedGlobalLocalizer(instantiate("globalloc", spec), spec)
