"""Single-wheel test data for ``rover-sim bench wheel``: reading a CSV of rig runs, the known wheel geometries.

A CSV has one row per run with at least the columns ``wheel``, ``slip_angle_deg``, ``slip`` and ``load_N``; the
measured ``drawbar_pull_N``, ``lateral_force_N`` and ``sinkage_mm`` are scored when present (the plot's spreads are
those of each condition's trials), ``travel_speed_mm_s`` is the carriage speed (10 mm/s when absent). The wheel's
geometry is a known wheel named in the ``wheel`` column (or by ``--wheel``), or given per row by ``radius_m``,
``width_m`` and ``grouser_height_m``. The shipped data set is the CMU one (``benchmarks/data/cmu_single_wheel``, its
README). Bad input is one :class:`~rover_sim.errors.ConfigError` naming the file, the row and the column.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

from rover_sim.errors import ConfigError
from rover_sim.resources import data_dir
from rover_sim.sim.soil_tables import MAX_LOAD_N, WheelParams
from rover_sim.sim.terramechanics_wr import K10_MINI_GROUSER, K10_MINI_SMOOTH

REQUIRED = ("wheel", "slip_angle_deg", "slip", "load_N")
MEASURED = ("drawbar_pull_N", "lateral_force_N", "sinkage_mm")
GEOMETRY = ("radius_m", "width_m", "grouser_height_m")
DEFAULT_SPEED_MM_S = 10.0
KNOWN_WHEELS: dict[str, WheelParams] = {
    "grouser": K10_MINI_GROUSER,
    "smooth": K10_MINI_SMOOTH,
    "k10_mini_grouser": K10_MINI_GROUSER,
    "k10_mini_smooth": K10_MINI_SMOOTH,
    "mer": WheelParams(),
}


def cmu_data_path() -> Path:
    """The shipped CMU single-wheel tests (``benchmarks/data/cmu_single_wheel/single_wheel_tests.csv``)."""
    return data_dir("benchmarks") / "data" / "cmu_single_wheel" / "single_wheel_tests.csv"


@dataclass(frozen=True)
class WheelTest:
    """One run of a single-wheel rig: the imposed condition, the wheel, and what was measured (None: not)."""

    wheel: str
    geometry: WheelParams
    slip_angle_deg: float
    slip: float
    load_n: float
    travel_speed_m_s: float
    condition: str  # runs of one condition (wheel, slip angle, commanded rate) share it: trials
    drawbar_pull_n: float | None = None
    lateral_force_n: float | None = None
    sinkage_mm: float | None = None

    @property
    def measured(self) -> dict[str, float] | None:
        m = {"drawbar_pull_N": self.drawbar_pull_n, "lateral_force_N": self.lateral_force_n,
             "sinkage_mm": self.sinkage_mm}  # fmt: skip
        return None if all(v is None for v in m.values()) else m


def _number(path: Path, line: int, column: str, text: str, lo: float, hi: float, hi_open: bool = False) -> float:
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise ConfigError(str(path), column, f"row {line}: {text!r} is not a number") from None
    if not math.isfinite(v) or v < lo or v > hi or (hi_open and v >= hi):
        rng = f"[{lo:g}, {hi:g})" if hi_open else f"[{lo:g}, {hi:g}]"
        raise ConfigError(str(path), column, f"row {line}: {v:g} is outside the allowed range {rng}")
    return v


def _geometry(path: Path, line: int, row: dict[str, str], name: str, wheel: str | None) -> WheelParams:
    if wheel is not None:
        return KNOWN_WHEELS[wheel]
    if all(row.get(c) not in (None, "") for c in GEOMETRY):
        r = _number(path, line, "radius_m", row["radius_m"], 0.01, 1.0)
        b = _number(path, line, "width_m", row["width_m"], 0.01, 1.0)
        h = _number(path, line, "grouser_height_m", row["grouser_height_m"], 0.0, 0.2 * r)
        return WheelParams(radius_m=r, width_m=b, grouser_height_m=h, flat_patch_m=0.0)
    if name not in KNOWN_WHEELS:
        known, cols = ", ".join(KNOWN_WHEELS), ", ".join(GEOMETRY)
        raise ConfigError(str(path), "wheel", f"row {line}: unknown wheel {name!r}: name one of {known}, "
                          f"give columns {cols}, or pass --wheel")  # fmt: skip
    return KNOWN_WHEELS[name]


def read_tests(path: str | Path | None = None, wheel: str | None = None) -> list[WheelTest]:
    """The rows of a single-wheel test CSV (default: the CMU data), in file order. ``wheel`` names one known
    geometry for every row (``KNOWN_WHEELS``) instead of the ``wheel`` column's."""
    p = Path(path) if path is not None else cmu_data_path()
    if wheel is not None and wheel not in KNOWN_WHEELS:
        raise ConfigError("--wheel", "wheel", f"unknown wheel {wheel!r}: choose one of {', '.join(KNOWN_WHEELS)}")
    if not p.is_file():
        raise ConfigError(str(p), "--data", "no such file")
    try:
        with p.open(newline="") as f:
            reader = csv.DictReader(f)
            columns = reader.fieldnames or []
            missing = [c for c in REQUIRED if c not in columns]
            if missing:
                raise ConfigError(str(p), missing[0], f"missing column (required: {', '.join(REQUIRED)})")
            rows = list(reader)
    except UnicodeDecodeError as e:
        raise ConfigError(str(p), "--data", f"not a text CSV file ({e.reason})") from None
    except csv.Error as e:
        raise ConfigError(str(p), "--data", f"not a readable CSV file ({e})") from None
    if not rows:
        raise ConfigError(str(p), "--data", "no data rows")
    tests = []
    for k, row in enumerate(rows):
        line = k + 2  # the header is line 1
        name = (row.get("wheel") or "").strip()
        if not name:
            raise ConfigError(str(p), "wheel", f"row {line}: empty")
        geom = _geometry(p, line, row, name, wheel)
        beta = _number(p, line, "slip_angle_deg", row["slip_angle_deg"], 0.0, 90.0)
        slip = _number(p, line, "slip", row["slip"], -1.0, 1.0, hi_open=True)
        load = _number(p, line, "load_N", row["load_N"], 3.0, MAX_LOAD_N)
        speed = DEFAULT_SPEED_MM_S
        if row.get("travel_speed_mm_s") not in (None, ""):
            speed = _number(p, line, "travel_speed_mm_s", row["travel_speed_mm_s"], 1.0, 1000.0)
        measured = {}
        for c in MEASURED:
            text = row.get(c)
            measured[c] = None if text in (None, "") else _number(p, line, c, text, -1e4, 1e4)
        rate = row.get("wheel_rate_deg_s")
        condition = f"{name}|{beta:g}|{rate if rate not in (None, '') else round(slip, 2)}"
        dp, lat, z = (measured[c] for c in MEASURED)
        tests.append(WheelTest(name if wheel is None else wheel, geom, beta, slip, load, speed / 1000.0, condition,
                               dp, lat, z))  # fmt: skip
    return tests
