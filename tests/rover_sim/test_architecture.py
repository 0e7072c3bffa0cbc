"""The architecture holds: module sizes, no private calls across modules, no import cycle (imports under
``TYPE_CHECKING`` and inside functions count), the packages' layers, no re-exports, pure ``nav``, and the onboard
stack's entry points take only :class:`Observation`."""

from __future__ import annotations

import ast
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from nav.trajectory import Pose
from rover_sim.runtime.onboard import Onboard
from rover_sim.runtime.plugins import make_planner, make_stereo, make_vo
from rover_sim.scenario.nav_spec import NavSpec
from rover_sim.world.observation import NotAnObservation, Observation

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("rover_sim", "nav", "terrains")
MAX_LINES = {"rover_sim": 500, "nav": 600, "terrains": 600}
# private attributes of third-party objects the code legitimately touches (MuJoCo's renderer context, a pool size)
# mujoco.Renderer (context, output size and viewport: render/gl.py set_viewport), multiprocessing
THIRD_PARTY_PRIVATE = {"_mjr_context", "_gl_context", "_width", "_height", "_rect", "_processes"}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = _modules()


@pytest.mark.parametrize("name", sorted(MODULES))
def test_module_size(name):
    n, limit = len(MODULES[name].read_text().splitlines()), MAX_LINES[name.split(".")[0]]
    assert n <= limit, f"{name} has {n} lines (> {limit}): split it along its seams"


def test_no_private_calls_across_modules():
    """No ``other._name`` access (self/cls aside) and no ``from x import _name`` within our packages."""
    bad = []
    for name, path in MODULES.items():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
                base = node.value
                if isinstance(base, ast.Name) and base.id in ("self", "cls"):
                    continue
                if node.attr in THIRD_PARTY_PRIVATE:
                    continue
                bad.append(f"{name}:{node.lineno} .{node.attr}")
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in PACKAGES:
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        bad.append(f"{name}:{node.lineno} from {node.module} import {alias.name}")
    assert not bad, "private names used across modules (add a public hook):\n" + "\n".join(bad)


def _imports(path: Path, module: str) -> set[str]:
    """Modules of our packages that ``module`` imports anywhere: at the top, inside functions (lazy imports) and
    under ``if TYPE_CHECKING`` (an annotation-only import is still a dependency)."""
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        else:
            continue
        for n in names:
            while n and n not in MODULES:
                n = n.rpartition(".")[0]
            if n and n != module and not module.startswith(n + ".") and n not in PACKAGES:
                out.add(n)
    return out


def test_no_import_cycle():
    graph = {m: _imports(p, m) for m, p in MODULES.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph.get(m, ())):
            if state.get(n) == 1:
                cycle = stack[stack.index(n) :] + [n]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if n not in state:
                visit(n)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


# The layers of rover_sim, lowest first: a package imports only from its own layer and the ones below. The world's
# physics and eyes (sim, render) know nothing of the scenario schema, the runtime or the applications.
LAYERS = {
    "sim": 0,
    "render": 1,
    "scenario": 2,
    "world": 3,
    "runtime": 4,
    "io": 4,
    "apps": 5,
    "env": 5,
    "env_world": 5,
    "bench": 6,
    "cli": 7,
}
ANY_LAYER = {"errors", "resources", "interrupts"}  # importable from every layer
# upward imports that stay for now, each with its reason
UPWARD = {
    ("rover_sim.runtime.runner", "rover_sim.apps.autonav"): "the runner runs an autonav command by calling "
    "apps.autonav.run_autonav (autonav sees the runner only through its AutonavRunner protocol); the runner "
    "restructuring hands command handlers to the runner instead",
}


def _layer(module: str) -> int | None:
    parts = module.split(".")
    if parts[0] != "rover_sim" or len(parts) < 2 or parts[1] in ANY_LAYER:
        return None
    return LAYERS.get(parts[1])


def test_layers():
    bad = []
    for name, path in MODULES.items():
        own = _layer(name)
        if own is None:
            continue
        for imported in _imports(path, name):
            theirs = _layer(imported)
            if theirs is not None and theirs > own and (name, imported) not in UPWARD:
                bad.append(f"{name} imports {imported}")
    order = " < ".join(", ".join(p for p, n in LAYERS.items() if n == level) for level in sorted(set(LAYERS.values())))
    assert not bad, f"imports against the layers ({order}):\n" + "\n".join(bad)


def test_world_packages_import_no_runner():
    """sim/ and render/ (the world's physics and eyes) import nothing from the runtime, apps, benchmarks or CLI."""
    for name, path in MODULES.items():
        if name.split(".")[:2] in (["rover_sim", "sim"], ["rover_sim", "render"]):
            for imported in _imports(path, name):
                top = imported.split(".")[:2]
                assert top[-1] not in ("runtime", "apps", "bench", "cli"), f"{name} imports {imported}"


def _defined_names(path: Path) -> set[str]:
    """Names a module defines itself (classes, functions, assignments), not the ones it imports."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            out.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                out.update(n.id for n in ast.walk(target) if isinstance(n, ast.Name))
    return out


def test_no_reexports():
    """``from rover_sim.x import name`` names something ``x`` defines (or a submodule): no module re-exports
    another's names, so each name has one home. Package ``__init__`` files of nav and terrains are their APIs."""
    files = [*MODULES.values(), *(ROOT / "tests").rglob("*.py"), *(ROOT / "examples").rglob("*.py")]
    files += [*(ROOT / "scripts").rglob("*.py")]
    bad = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text())):
            if not (isinstance(node, ast.ImportFrom) and node.level == 0 and node.module in MODULES):
                continue
            if not node.module.startswith("rover_sim") or MODULES[node.module].name == "__init__.py":
                continue
            own = _defined_names(MODULES[node.module])
            for alias in node.names:
                if alias.name not in own and f"{node.module}.{alias.name}" not in MODULES:
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.module} does not define {alias.name}")
    assert not bad, "import each name from the module that defines it:\n" + "\n".join(bad)


def test_nav_is_pure():
    for name, path in MODULES.items():
        if name.split(".")[0] != "nav":
            continue
        for imported in _imports(path, name) | {
            a.name for n in ast.walk(ast.parse(path.read_text())) if isinstance(n, ast.Import) for a in n.names
        }:
            assert not imported.startswith(("rover_sim", "mujoco", "rerun")), f"{name} imports {imported}"


# nav's third-party imports: numpy, scipy and OpenCV; numba only for the compiled SAD engine, which the stereo
# pipeline can do without (NAV_STEREO_ENGINE=opencv, the same results).
NAV_THIRD_PARTY = {"numpy", "scipy", "cv2"}
NAV_NUMBA_MODULES = {"nav.stereo.fused"}


def test_nav_needs_only_numpy_scipy_opencv():
    for name, path in MODULES.items():
        if name.split(".")[0] != "nav":
            continue
        tree = ast.parse(path.read_text())
        top = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        froms = [n for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module and not n.level]
        top |= {n.module.split(".")[0] for n in froms}
        third = top - set(sys.stdlib_module_names) - {"nav", "__future__"}
        allowed = NAV_THIRD_PARTY | ({"numba"} if name in NAV_NUMBA_MODULES else set())
        assert third <= allowed, f"{name} imports {sorted(third - allowed)}"


def test_onboard_imports_no_simulator_or_truth():
    allowed_rover_sim = {"rover_sim.world.observation"}
    for mod in ("rover_sim.runtime.onboard", "rover_sim.world.observation"):
        ours = {m for m in _imports(MODULES[mod], mod) if m.startswith("rover_sim")}
        assert ours <= allowed_rover_sim, f"{mod} imports {ours - allowed_rover_sim}"


@pytest.fixture
def onboard():
    nav = NavSpec()
    start = Pose(0.0, np.zeros(3), np.array([1.0, 0, 0, 0]))
    return Onboard(start, make_vo(nav.vo), make_stereo(nav.stereo), lambda: make_planner(nav.planner))


def test_onboard_refuses_anything_but_an_observation(onboard):
    truthy = SimpleNamespace(t_s=0.0, imu=(), encoders=(), images={}, position_m=np.zeros(3), wheel_slip=np.zeros(6))

    class Smuggler(Observation):
        pass

    smuggled = Smuggler(t_s=0.0)
    object.__setattr__(smuggled, "truth_position_m", np.zeros(3))
    for bad in (truthy, smuggled, {"t_s": 0.0}):
        with pytest.raises(NotAnObservation, match="accepts only"):
            onboard.observe(bad)
        with pytest.raises(NotAnObservation):
            onboard.vo_step(bad, "navcam")
        with pytest.raises(NotAnObservation):
            onboard.plan(bad, np.zeros(2), ("hazcam_front",))
    onboard.observe(Observation(t_s=0.0))  # the real thing is accepted


def test_observation_holds_no_truth_fields():
    names = set(Observation.__dataclass_fields__)
    assert names == {
        "t_s",
        "imu",
        "encoders",
        "images",
        "mast_pan_deg",
        "mast_elevation_deg",
        "start_pose",
        "sun_direction_world",
    }
