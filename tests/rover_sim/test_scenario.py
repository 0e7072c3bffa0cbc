"""Scenario loading: every catalogue file validates; malformed input gives a clean ConfigError, never a traceback."""

from __future__ import annotations

import tomllib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rover_sim.errors import ConfigError
from rover_sim.scenario.loading import catalogue, load_scenario, parse_override, scenario_from_dict

MINIMAL = {"name": "t", "commands": [{"type": "drive", "distance_m": 1.0}]}


@pytest.mark.parametrize("name", catalogue())
def test_catalogue_scenarios_validate(name):
    s = load_scenario(name)
    assert s.name == name
    assert s.commands


def test_error_names_file_field_and_range(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text('name = "bad"\n[terrain.slope]\nslope_deg = 60\n[[commands]]\ntype = "drive"\ndistance_m = 1\n')
    with pytest.raises(ConfigError) as e:
        load_scenario(p)
    msg = str(e.value)
    assert "bad.toml" in msg and "terrain.slope.slope_deg" in msg and "45" in msg


def test_unknown_key_and_unknown_command_are_rejected():
    with pytest.raises(ConfigError, match="nav.turbo"):
        scenario_from_dict({**MINIMAL, "nav": {"turbo": True}})
    with pytest.raises(ConfigError, match="commands.0"):
        scenario_from_dict({"name": "t", "commands": [{"type": "teleport"}]})


def test_overrides_and_seed():
    s = scenario_from_dict(MINIMAL, overrides=["nav.vo_step_m=0.5", "terrain.slope.slope_deg=12", "seed=9"])
    assert s.nav.vo_step_m == 0.5 and s.terrain.slope.slope_deg == 12 and s.seed == 9
    assert parse_override("nav.camera=hazcam_front") == ("nav.camera", "hazcam_front")
    with pytest.raises(ConfigError, match="nav.vo_step_m"):
        scenario_from_dict(MINIMAL, overrides=["nav.vo_step_m=2.0"])


def test_missing_file_lists_known_scenarios():
    with pytest.raises(ConfigError, match="known scenarios"):
        load_scenario("no_such_scenario")


def test_broken_toml_syntax(tmp_path):
    p = tmp_path / "x.toml"
    p.write_text("name = \n[[[")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_scenario(p)


_toml_value = st.recursive(
    st.none() | st.booleans() | st.integers(-(10**6), 10**6) | st.floats(allow_nan=True) | st.text(max_size=8),
    lambda children: st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=8), children, max_size=3),
    max_leaves=8,
)
_keys = st.sampled_from(
    [
        "name",
        "seed",
        "terrain",
        "terrain.slope.slope_deg",
        "terrain.cell_size_m",
        "sun.elevation_deg",
        "nav.vo_step_m",
        "nav.camera",
        "commands",
        "commands.0.distance_m",
        "commands.0.type",
        "keep_out",
        "pass.max_vo_error_pct",
        "start.x_m",
        "physics.timestep_s",
        "nav",
        "bogus",
    ]
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(key=_keys, value=_toml_value)
def test_fuzzed_fields_give_clean_errors(key, value):
    tree = {"name": "fuzz", "commands": [{"type": "drive", "distance_m": 1.0}], "terrain": {"size_m": [8, 8]}}
    node = tree
    parts = key.split(".")
    try:
        for p in parts[:-1]:
            node = node[int(p)] if isinstance(node, list) else node.setdefault(p, {})
        if isinstance(node, list):
            node[int(parts[-1])] = value
        else:
            node[parts[-1]] = value
    except (TypeError, KeyError, IndexError, AttributeError, ValueError):
        return
    try:
        scenario_from_dict(tree)
    except ConfigError as e:
        assert "<dict>" in str(e)


@settings(max_examples=80, deadline=None)
@given(text=st.text(max_size=60))
def test_fuzzed_toml_text_gives_clean_errors(tmp_path_factory, text):
    p = tmp_path_factory.mktemp("fz") / "f.toml"
    p.write_text(text)
    try:
        tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        pass
    try:
        load_scenario(p)
    except ConfigError:
        pass
