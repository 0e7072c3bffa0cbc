"""Loading a scenario: ``scenarios/<name>.toml`` or a path, ``--set dotted.key=value`` overrides and ``--seed``; errors
name the file, the field and the allowed range. The catalogue is every TOML file under ``scenarios/``."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from rover_sim.errors import ConfigError, UnknownScenario
from rover_sim.resources import scenarios_dir
from rover_sim.scenario.schema import Scenario

SCENARIOS_DIR = scenarios_dir()


def _list_index(node: list, key: str, dotted: str, where: str) -> int:
    """``key`` as an index into ``node`` (the list at ``where``), or a ConfigError naming the list's length."""
    try:
        i = int(key)
    except ValueError:
        problem = f"'{where}' is a list: '{key}' is not an index (0..{len(node) - 1})"
        raise ConfigError("--set", dotted, problem) from None
    if not 0 <= i < len(node):
        n = len(node)
        raise ConfigError(
            "--set", dotted, f"index {i} out of range: '{where}' has {n} item{'s' if n != 1 else ''} (0..{n - 1})"
        )
    return i


def _set_dotted(tree: dict, dotted: str, value: Any) -> None:
    keys = dotted.split(".")
    if not all(keys):
        raise ConfigError("--set", dotted, "empty key (expected dotted.key=value)")
    node: Any = tree
    for depth, k in enumerate(keys[:-1]):
        where = ".".join(keys[:depth]) or "(top level)"
        if isinstance(node, list):
            node = node[_list_index(node, k, dotted, where)]
        else:
            node = node.setdefault(k, {})
        if not isinstance(node, dict | list):
            raise ConfigError("--set", dotted, f"'{k}' is a value, not a table")
    last = keys[-1]
    if isinstance(node, list):
        node[_list_index(node, last, dotted, ".".join(keys[:-1]))] = value
    else:
        node[last] = value


def parse_override(text: str) -> tuple[str, Any]:
    """``a.b=1.5`` -> ("a.b", 1.5); the value is parsed as TOML (numbers, booleans, strings, arrays)."""
    if "=" not in text:
        raise ConfigError("--set", text, "expected dotted.key=value")
    key, raw = text.split("=", 1)
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw  # a bare string
    return key.strip(), value


def _describe(err: ValidationError) -> tuple[str, str]:
    first = err.errors()[0]
    loc = ".".join(str(p) for p in first["loc"]) or "(top level)"
    msg = first["msg"]
    ctx = first.get("ctx") or {}
    bounds = ", ".join(f"{k} {v}" for k, v in ctx.items() if k in ("ge", "gt", "le", "lt", "expected"))
    if bounds:
        msg = f"{msg} (allowed: {bounds})"
    if first.get("input") is not None and not isinstance(first.get("input"), dict | list):
        msg = f"{msg}; got {first['input']!r}"
    more = len(err.errors()) - 1
    if more:
        msg += f" (+{more} more problem{'s' if more > 1 else ''})"
    return loc, msg


def _normalise_nav(tree: dict) -> None:
    """``[nav] vo = false`` / ``vo = "pkg.mod:Class"`` shorthands become tables, so ``--set nav.vo.x=...`` works."""
    nav = tree.get("nav")
    if not isinstance(nav, dict):
        return
    for part in ("vo", "stereo", "planner"):
        value = nav.get(part)
        if isinstance(value, bool) and part == "vo":
            nav[part] = {"enabled": value}
        elif isinstance(value, str):
            nav[part] = {"impl": value}


def plugin_overrides(vo: str | None = None, stereo: str | None = None, planner: str | None = None) -> list[str]:
    """``--set`` overrides that select the given implementations (``--vo`` also turns VO on)."""
    out = []
    if vo:
        out += ["nav.vo.enabled=true", f'nav.vo.impl="{vo}"']
    if stereo:
        out.append(f'nav.stereo.impl="{stereo}"')
    if planner:
        out.append(f'nav.planner.impl="{planner}"')
    return out


def _blamed_override(loc: str, overrides: list[str], flags: list[str]) -> str | None:
    """The flag (``--set key=value``, ``--seed N``) whose key the invalid field ``loc`` belongs to, if any: the
    key's parts appear in order in ``loc`` (a command's type tag may sit between them), or ``loc`` is the start of
    the key (an unknown key is reported at its first unknown part)."""
    parts = loc.split(".")
    for text, flag in reversed(list(zip(overrides, flags, strict=True))):
        key = parse_override(text)[0].split(".")
        it = iter(parts)
        if all(k in it for k in key) or key[: len(parts)] == parts:
            return flag
    return None


def scenario_from_dict(
    data: dict, source: str = "<dict>", overrides: list[str] | None = None, flags: list[str] | None = None
) -> Scenario:
    """Validate ``data`` with ``overrides`` (``dotted.key=value``) applied. A field made invalid by an override is
    reported against the flag that set it (``flags[i]`` for ``overrides[i]``; default ``--set <override>``),
    not against ``source``."""
    overrides = list(overrides or [])
    flags = list(flags) if flags is not None else [f"--set {o}" for o in overrides]
    tree = json.loads(json.dumps(data))  # deep copy of plain data
    _normalise_nav(tree)
    for text in overrides:
        key, value = parse_override(text)
        _set_dotted(tree, key, value)
    try:
        return Scenario.model_validate(tree)
    except ValidationError as err:
        loc, msg = _describe(err)
        raise ConfigError(_blamed_override(loc, overrides, flags) or source, loc, msg) from None


def load_scenario(
    name_or_path: str | Path,
    overrides: list[str] | None = None,
    seed: int | None = None,
    flags: list[str] | None = None,
) -> Scenario:
    """Load ``scenarios/<name>.toml`` or a path; apply ``--set`` overrides and ``--seed``. An invalid value is
    reported against its flag: ``flags[i]`` for ``overrides[i]`` (default ``--set <override>``), ``--seed N``."""
    path = Path(name_or_path)
    if not path.suffix:
        path = SCENARIOS_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        raise UnknownScenario(str(name_or_path), catalogue(), is_name=not Path(name_or_path).suffix)
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ConfigError(str(path), "(syntax)", f"not valid TOML: {err}") from None
    extra = list(overrides or [])
    flags = list(flags) if flags is not None else [f"--set {o}" for o in extra]
    if seed is not None:
        extra.append(f"seed={seed}")
        flags.append(f"--seed {seed}")
    return scenario_from_dict(data, str(path), extra, flags)


def catalogue() -> list[str]:
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))
