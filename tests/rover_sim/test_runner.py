"""The closed-loop runner on a tiny scenario: outputs, the rerun recording read back, determinism, clean stops."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nav.trajectory import read_tum
from rover_sim.io.rrd import entity_row_counts
from rover_sim.runtime.run import run_scenario
from rover_sim.runtime.runner import Mission
from rover_sim.scenario.loading import scenario_from_dict

TINY = {
    "name": "tiny",
    "seed": 3,
    "terrain": {
        "size_m": [8, 6],
        "cell_size_m": 0.05,
        "slope": {"slope_deg": 12, "azimuth_deg": 0},
        "rocks": {
            "cover_fraction": 0.05,
            "min_height_m": 0.05,
            "max_height_m": 0.12,
            "exclusion_zones": [[-2, 0, 1.0]],
        },
    },
    "start": {"x_m": -2.0, "y_m": 0.0},
    "nav": {"vo": True, "vo_step_m": 0.3},
    "commands": [{"type": "drive", "distance_m": 0.6}],
    "keep_out": [{"name": "marker", "x_m": 2.5, "y_m": 2.0, "radius_m": 0.5}],
    "pass": {"max_vo_error_pct": 3.0, "max_false_positives": 0},
}


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("tiny")
    metrics = run_scenario(scenario_from_dict(TINY), out, record=True)
    return out, metrics


def test_outputs_written(tiny_run):
    out, m = tiny_run
    data = json.loads((out / "metrics.json").read_text())
    for key in (
        "scenario",
        "seed",
        "distance_m",
        "dr_error_pct",
        "vo_error_pct",
        "vo_convergence_pct",
        "max_slip_pct",
        "mean_slip_pct",
        "passed",
        "reason",
        "wall_s",
    ):
        assert key in data
    assert data["scenario"] == "tiny" and data["seed"] == 3
    assert 0.4 < m.distance_m < 0.7  # 0.6 m commanded on a 12 deg sand slope: some slip
    assert m.vo_steps == 2 and m.vo_accepted == 2
    assert m.passed, m.reason
    truth = read_tum(out / "trajectories" / "truth.tum")
    vo = read_tum(out / "trajectories" / "vo.tum")
    dr = read_tum(out / "trajectories" / "dead_reckoning.tum")
    assert len(truth) > 10 and len(vo) > 10
    for traj in (truth, vo, dr):
        assert np.all(np.diff(traj.t_s) > 0)  # strictly increasing timestamps
    assert np.linalg.norm(vo.positions_xyz[-1] - truth.positions_xyz[-1]) < 0.02
    for p in ("error_vs_distance.png", "paths.png", "slip.png"):
        assert (out / "plots" / p).stat().st_size > 1000
    assert json.loads((out / "scenario.json").read_text())["name"] == "tiny"


def test_recording_has_the_entity_tree(tiny_run):
    out, m = tiny_run
    counts = entity_row_counts(out / "recording.rrd")
    ticks = counts["/world/rover"]
    assert ticks > 50  # 8 Hz over the drive
    assert counts["/world/terrain"] >= 1
    assert counts["/world/keep_out/marker"] >= 1
    assert counts["/world/rover/navcam/left/image"] == 3  # the initial pair + one per VO step
    assert counts["/world/rover/navcam/right/image"] == 3
    assert counts["/world/rover/navcam/left/features"] == 2
    assert counts["/world/rover/navcam/left/depth"] == 3  # dense SAD stereo of each pair
    assert counts["/world/points/navcam"] == 3
    for name in ("truth", "dead_reckoning", "vo"):
        assert any(k.startswith(f"/world/trajectories/{name}/") for k in counts), name
    assert counts.get("/events", 0) >= 1
    assert any(k.startswith("/plots/slip") for k in counts)


def test_same_seed_same_metrics(tiny_run, tmp_path):
    _, first = tiny_run
    again = run_scenario(scenario_from_dict(TINY), tmp_path, record=False)
    a, b = first.deterministic_dict(), again.deterministic_dict()
    a.pop("wall_s"), b.pop("wall_s")
    assert a == b


def test_interrupt_stops_cleanly_and_keeps_what_was_recorded(tmp_path):
    calls = {"n": 0}

    def progress(t_s, _msg):
        calls["n"] += 1
        if calls["n"] == 20:
            raise KeyboardInterrupt

    sc = scenario_from_dict(TINY)
    mission = Mission(sc, progress=progress)
    try:
        m = mission.run()
    finally:
        mission.renderer.close()
    assert not m.passed and "interrupted" in m.reason
    assert len(mission.evaluator.truth) >= 19
