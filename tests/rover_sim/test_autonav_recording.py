"""A sol's drive logs every autonav cycle's hazcam pair but the cycle's detail (depth, points, goodness map, votes)
only every SOL_DETAIL_EVERY-th cycle; other drives log the detail every cycle."""

from __future__ import annotations

import copy

import pytest

from rover_sim.apps.autonav import SOL_DETAIL_EVERY
from rover_sim.io.recorder_protocol import NullRecorder
from rover_sim.runtime.runner import Mission
from rover_sim.scenario.loading import scenario_from_dict

pytestmark = pytest.mark.render

FIELD = {
    "name": "autonav_logging",
    "seed": 7,
    "terrain": {
        "size_m": [10, 7],
        "cell_size_m": 0.05,
        "roughness": {"rms_m": 0.01, "correlation_length_m": 1.5},
        "rocks": {"cover_fraction": 0.0},
        "material": {"kind": "bedrock"},
    },
    "start": {"x_m": -2.5, "y_m": 0.0, "yaw_deg": 0},
    "nav": {"vo": False, "camera": "hazcam_front"},
    "commands": [{"type": "autonav", "x_m": 3.5, "y_m": 0.0, "tolerance_m": 0.3, "max_cycles": 6}],
}


class CountingRecorder(NullRecorder):
    def __init__(self) -> None:
        self.pairs, self.depths, self.goodness = 0, 0, 0

    def log_stereo_images(self, name, t_s, step, left_u8, right_u8, disparity_px=None) -> None:  # noqa: ANN001
        self.pairs += 1
        self.depths += disparity_px is not None

    def log_goodness(self, *args, **kwargs) -> None:  # noqa: ANN002, ANN003
        self.goodness += 1


def _run(data: dict) -> tuple[int, CountingRecorder]:
    rec = CountingRecorder()
    mission = Mission(scenario_from_dict(data), rec)
    try:
        mission.run()
    finally:
        mission.close()
    return mission.autonav_stats.cycles, rec


def test_sol_drives_log_autonav_detail_every_few_cycles() -> None:
    cycles, rec = _run(FIELD)
    assert cycles >= 5 and rec.pairs == rec.depths == rec.goodness == cycles  # a plain drive: every cycle
    sol = copy.deepcopy(FIELD)
    sol["sol"] = {"max_time_s": 80000.0}
    sol_cycles, sol_rec = _run(sol)
    assert sol_cycles == cycles and sol_rec.pairs == cycles  # the same drive, every pair logged
    expected = len(range(0, cycles, SOL_DETAIL_EVERY))  # no boxed-in cycle on this open field
    assert sol_rec.depths == sol_rec.goodness == expected < cycles
