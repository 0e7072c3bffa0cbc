"""Replayed VOs: another estimator on the identical inputs of a run (rover_sim.bench.replay)."""

from __future__ import annotations

from pathlib import Path

import pytest

from rover_sim.bench.seeded import Case, run_seeded

SHORT_SHADOW = Case("shadow_1m", "sol235_shadow", ("commands.0.distance_m=1.2",))


@pytest.fixture(autouse=True)
def _plugins_importable(monkeypatch):
    monkeypatch.syspath_prepend(str(Path(__file__).parent))


def test_replaying_the_builtin_vo_reproduces_the_run_and_a_broken_one_is_scored(tmp_path):
    """MER VO replayed on its own run's inputs gives that run's VO figures to the digit (the replay sees exactly
    what the onboard stack saw); a VO that refuses every step is scored as dead reckoning; a 1 % scale error shows."""
    replay = {
        "same": "builtin",
        "refuse": "known_bad_vos:RefuseAllVO",
        "scale": "known_bad_vos:ScaleErrorVO",
        "yaw": "known_bad_vos:YawBiasVO",
    }
    (runs,) = run_seeded([SHORT_SHADOW], (0,), ("flight",), tmp_path, workers=0, replay=replay)
    own, same = runs.metrics[0], runs.replays["same"].metrics[0]
    for key in ("vo_error_pct", "dr_error_pct", "vo_convergence_pct", "false_positives", "vo_accepted",
                "kitti_segment_error_pct", "rms_position_error_m", "vo_textured_steps",
                "vo_textured_convergence_pct", "passed", "reason"):  # fmt: skip
        assert same[key] == own[key], key
    refuse = runs.replays["refuse"].metrics[0]
    assert refuse["vo_convergence_pct"] == 0.0 and refuse["vo_error_pct"] == pytest.approx(own["dr_error_pct"])
    assert not refuse["passed"]  # sol235_shadow needs VO convergence >= 90 %
    scale = runs.replays["scale"].metrics[0]
    assert scale["vo_error_pct"] > own["vo_error_pct"] + 0.5
    yaw = runs.replays["yaw"].metrics[0]  # 0.05 deg per step more rotation error, whatever the step's own error
    assert (
        own["vo_rotation_error_deg_per_m"] is not None
        and same["vo_rotation_error_deg_per_m"] == own["vo_rotation_error_deg_per_m"]
    )
    assert yaw["vo_rotation_error_deg_per_m"] > own["vo_rotation_error_deg_per_m"] + 0.02


@pytest.mark.slow
def test_replayed_vo_is_judged_on_the_runs_textured_steps(tmp_path):
    """meridiani_plains is judged on its textured steps (a truth fact of each pair): MER VO replayed on the run's
    pairs is judged on the same steps, and so passes or fails exactly as the run does."""
    short = Case("meridiani", "meridiani_plains", ())
    (runs,) = run_seeded([short], (0,), ("flight",), tmp_path, workers=0, replay={"same": "builtin"})
    own, same = runs.metrics[0], runs.replays["same"].metrics[0]
    assert own["vo_textured_steps"] > 0
    for key in ("vo_textured_steps", "vo_textured_accepted", "vo_textured_convergence_pct", "false_positives"):
        assert same[key] == own[key], key
