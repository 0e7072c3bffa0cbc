"""Seed sets of the benchmarks, read from ``benchmarks/provenance.toml`` (the one place that also says what every
tuned parameter was tuned on), and the ``--seeds`` option: a count or a list/range of seeds.

Three disjoint sets: ``tuning`` (runs parameters may have been chosen on, the catalogue's own seed 0 among them),
``published`` (the docs' tables) and ``gate`` (the CI regression gate). A count takes the first N of the command's
default set; an explicit list is reported under the set that contains it, else as ``custom``.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from functools import cache
from typing import Literal

from rover_sim.errors import ConfigError
from rover_sim.resources import data_dir

SeedSetName = Literal["tuning", "published", "gate"]
SEED_SET_NAMES: tuple[SeedSetName, ...] = ("tuning", "published", "gate")
MAX_SEEDS = 64  # a run of more seeds than this is a sweep (`rover-sim sweep`), not a benchmark


@dataclass(frozen=True)
class SeedRange:
    first: int
    last: int

    def take(self, n: int) -> list[int]:
        if n > self.last - self.first + 1:
            raise ConfigError("--seeds", str(n), f"at most {self.last - self.first + 1} seeds in this set")
        return list(range(self.first, self.first + n))

    def __contains__(self, seed: object) -> bool:
        return isinstance(seed, int) and self.first <= seed <= self.last


@dataclass(frozen=True)
class Seeds:
    """The seeds of a benchmark run and the set they belong to."""

    values: tuple[int, ...]
    seed_set: str  # one of SEED_SET_NAMES or "custom"

    def __len__(self) -> int:
        return len(self.values)


def provenance_path():  # noqa: ANN201
    return data_dir("benchmarks") / "provenance.toml"


@cache
def provenance() -> dict:
    """``benchmarks/provenance.toml`` as a dict."""
    return tomllib.loads(provenance_path().read_text())


def seed_set(name: SeedSetName, table: str = "seed_sets") -> SeedRange:
    entry = provenance()[table][name]
    return SeedRange(int(entry["first"]), int(entry["last"]))


def classify(seeds: tuple[int, ...], table: str = "seed_sets") -> str:
    """The named set that holds every seed of ``seeds``, else ``custom``."""
    for name, entry in provenance()[table].items():
        rng = SeedRange(int(entry["first"]), int(entry["last"]))
        if all(s in rng for s in seeds):
            return name
    return "custom"


def parse_seeds(text: str | None, default_set: SeedSetName, default_count: int, option: str = "--seeds") -> Seeds:
    """``--seeds`` text: ``N`` (the first N of ``default_set``), ``A-B`` (inclusive range) or ``A,B,C``; None gives
    the first ``default_count`` of ``default_set``. A bad value is a :class:`ConfigError` naming the option."""
    allowed = f"a count 1-{MAX_SEEDS}, a range A-B or a list A,B,C of seeds >= 0"
    if text is None or text.strip().isdigit():
        n = default_count if text is None else int(text)
        if not 1 <= n <= MAX_SEEDS:
            raise ConfigError(option, str(text), f"expected {allowed}")
        return Seeds(tuple(seed_set(default_set).take(n)), default_set)
    try:
        if "-" in text and "," not in text:
            a, b = (int(p) for p in text.split("-", 1))
            values = list(range(a, b + 1))
        else:
            values = [int(p) for p in text.split(",") if p.strip()]
    except ValueError:
        raise ConfigError(option, text, f"expected {allowed}") from None
    if not values or len(values) > MAX_SEEDS or min(values) < 0 or len(set(values)) != len(values):
        raise ConfigError(option, text, f"expected {allowed}, no seed twice")
    chosen = tuple(values)
    return Seeds(chosen, classify(chosen))
