"""``bench globalloc``'s scoring and verdict: a localiser that returns its prior fails; the verdict's bars bite."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.globalloc import OrbitalMap, Raster
from rover_sim.bench.globalloc import Stop, draw_prior, run_stop, summarise
from rover_sim.bench.globalloc_sites import TERRAINS, stops_xy_yaw
from rover_sim.cli.orbital import parse_seeds
from rover_sim.errors import ConfigError, PluginError
from rover_sim.runtime.acceptance.bars import GLOBALLOC, judge_globalloc
from rover_sim.runtime.plugins import make_global_localizer


def tiny_map() -> OrbitalMap:
    r = Raster(np.zeros((8, 8), np.float32), 0.0, 0.0, 0.25)
    return OrbitalMap(r, r, np.array([0.0, 0.0, -1.0]), 0.25, 0.1, 0.001, 0.5)


def stops(terrain: str) -> list[Stop]:
    out = []
    for seed in range(100, 108):
        for k, (x, y, yaw) in enumerate(stops_xy_yaw(seed, 5)):
            truth = np.array([x, y, yaw])
            out.append(Stop(terrain, seed, k, [], np.eye(3), draw_prior(seed, k, truth), truth))
    return out


def test_priors_are_2_to_35_m_and_3_deg_off():
    for s in stops("rocky_plains"):
        d = float(np.hypot(*(s.prior_xy_yaw[:2] - s.truth_xy_yaw[:2])))
        assert 2.0 <= d <= 35.0
        assert abs(s.prior_xy_yaw[2] - s.truth_xy_yaw[2]) <= math.radians(3.0) + 1e-12


def test_do_nothing_localizer_fails_the_bench():
    loc = make_global_localizer("tests.plugins.do_nothing_localizer:DoNothing")
    blocks = {}
    for t in TERRAINS:
        rows = [run_stop(loc, s, tiny_map()) for s in stops(t)]
        blocks[t] = summarise(rows)
        assert blocks[t]["false_fixes"] == blocks[t]["stops"] == 40
    passed, reasons = judge_globalloc(blocks)
    assert not passed
    assert any("false fixes" in r for r in reasons)


def test_verdict_passes_good_figures_and_needs_enough_stops():
    good = {"stops": 40, "fixed": 39, "success": 39, "false_fixes": 0, "median_error_m": 0.1, "p90_error_m": 0.3,
            "compute_s_median": 5.0, "seeds": list(range(8))}  # fmt: skip
    refused = dict(good, fixed=0, success=0, median_error_m=None, p90_error_m=None)
    ok, reasons = judge_globalloc({"rocky_plains": good, "crater_rim": good, "dune_field": refused,
                                   "featureless_plain": refused})  # fmt: skip
    assert ok, reasons
    assert not judge_globalloc({"rocky_plains": dict(good, stops=39)})[0]
    assert not judge_globalloc({"rocky_plains": dict(good, success=37)})[0]
    assert not judge_globalloc({"dune_field": dict(refused, false_fixes=1)})[0]
    assert not judge_globalloc({"crater_rim": dict(good, p90_error_m=GLOBALLOC.max_p90_error_m + 0.01)})[0]


def test_a_plugin_answering_outside_the_protocol_is_named():
    class Bad:
        def localize(self, *a):  # noqa: ANN002, ANN201
            return "somewhere"

    from rover_sim.runtime.plugins import GuardedGlobalLocalizer

    with pytest.raises(PluginError, match="status"):
        run_stop(GuardedGlobalLocalizer(Bad(), "bad"), stops("rocky_plains")[0], tiny_map())


def test_seed_option_parsing():
    assert parse_seeds("100-103") == [100, 101, 102, 103]
    assert parse_seeds("1,5") == [1, 5]
    with pytest.raises(ConfigError, match="--seeds"):
        parse_seeds("a-b")
