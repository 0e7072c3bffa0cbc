"""The rock survey's evaluation against the terrain's rock list (ground truth): extraction recall and precision,
match and chain errors (:mod:`rover_sim.apps.survey`). The only place the survey's estimates meet the truth: a
site's estimated frame is mapped onto the true world through the truth pose composed with the inverse onboard
pose, and extracted rocks are associated with the generated ones."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from nav.rocks import Pose4, RockParams, SiteChain, SiteMatch, observation_quality
from rover_sim.apps.survey import SiteSurvey
from terrains import Rock, Terrain

ASSOCIATION_MARGIN_M = 0.3  # an extracted rock is a generated one if within its footprint radius plus this ...
ASSOCIATION_RANGE_FRAC = 0.02  # ... plus this fraction of the range (stereo range error grows with range)


@dataclass(frozen=True)
class ExtractionEval:
    """Counts and per-rock figures of one site (or of several, summed)."""

    n_true: int  # generated rocks taller than min_height_m within max_range_m
    n_found: int  # ... of them associated with an extracted rock
    n_extracted: int  # extracted rocks within max_range_m
    n_correct: int  # ... of them associated with a generated rock (any height)
    rms_m: list[float]  # model RMS of the extracted rocks associated with rocks taller than min_height_m
    type_match: list[bool]  # chosen model type == generating shape, same rocks
    range_m: list[float]  # their range
    missed: list[tuple[str, float, float]]  # (shape, height, range) of the generated rocks not found
    shapes: list[tuple[str, str]] = field(default_factory=list)  # (generating shape, chosen model), same rocks
    well_observed: list[bool] = field(default_factory=list)  # nav.rocks.RockObservation.well_observed, same rocks

    @property
    def recall(self) -> float:
        return self.n_found / self.n_true if self.n_true else math.nan

    @property
    def precision(self) -> float:
        return self.n_correct / self.n_extracted if self.n_extracted else math.nan

    def __add__(self, other: ExtractionEval) -> ExtractionEval:
        return ExtractionEval(
            self.n_true + other.n_true,
            self.n_found + other.n_found,
            self.n_extracted + other.n_extracted,
            self.n_correct + other.n_correct,
            self.rms_m + other.rms_m,
            self.type_match + other.type_match,
            self.range_m + other.range_m,
            self.missed + other.missed,
            self.shapes + other.shapes,
            self.well_observed + other.well_observed,
        )


def rocks_in_true_frame(site: SiteSurvey) -> np.ndarray:
    """(N, 3) extracted rock base centres mapped into the true world (evaluation only)."""
    W = site.estimated_to_true()
    c = np.array([r.model.centre_xyz_m for r in site.rocks]).reshape(-1, 3)
    return c @ W[:3, :3].T + W[:3, 3]


def associate(site: SiteSurvey, truth: list[Rock]) -> np.ndarray:
    """Index into ``truth`` of each extracted rock of ``site`` (-1: none), one-to-one, nearest first.

    Gate: the generated rock's footprint radius plus ``ASSOCIATION_MARGIN_M`` plus ``ASSOCIATION_RANGE_FRAC`` of the
    range from the site (horizontal distances between model centre and rock centre, in the true frame).
    """
    out = np.full(len(site.rocks), -1, dtype=int)
    if not site.rocks or not truth:
        return out
    est = rocks_in_true_frame(site)[:, :2]
    txy = np.array([[r.x_m, r.y_m] for r in truth])
    cam = site.T_world_rover_true[:2, 3]
    dist = np.linalg.norm(est[:, None, :] - txy[None, :, :], axis=2)
    gate = (
        np.array([r.footprint_radius_m for r in truth])[None, :]
        + ASSOCIATION_MARGIN_M
        + ASSOCIATION_RANGE_FRAC * np.linalg.norm(est - cam, axis=1)[:, None]
    )
    cost = np.where(dist <= gate, dist, 1e6)
    rows, cols = linear_sum_assignment(cost)
    ok = cost[rows, cols] < 1e6
    out[rows[ok]] = cols[ok]
    return out


def evaluate_extraction(
    site: SiteSurvey,
    terrain: Terrain,
    max_range_m: float = 30.0,
    min_height_m: float = 0.2,
    rocks_params: RockParams = RockParams(),
) -> ExtractionEval:
    """Recall (generated rocks taller than ``min_height_m`` within ``max_range_m`` of the site), precision
    (extracted rocks within ``max_range_m`` that are a generated rock), model RMS and type agreement (with the
    estimator's own judgement of whether each rock was well observed, :func:`nav.rocks.observation_quality`)."""
    truth = terrain.rocks
    idx = associate(site, truth)
    cam = site.T_world_rover_true[:2, 3]
    t_range = np.array([math.hypot(r.x_m - cam[0], r.y_m - cam[1]) for r in truth])
    target = (t_range <= max_range_m) & np.array([r.height_m > min_height_m for r in truth])
    found_set = {int(i) for i in idx if i >= 0}
    est = rocks_in_true_frame(site)
    e_range = np.linalg.norm(est[:, :2] - cam, axis=1) if len(est) else np.zeros(0)
    in_range = e_range <= max_range_m
    rms, types, ranges, shapes, well = [], [], [], [], []
    for k, i in enumerate(idx):
        if i >= 0 and target[i]:
            rock = site.rocks[k]
            rms.append(rock.model.rms_m)
            types.append(rock.model.shape == truth[i].shape)
            ranges.append(float(t_range[i]))
            shapes.append((truth[i].shape, rock.model.shape))
            well.append(observation_quality(rock, site.sensor_xyz_m, rocks_params).well_observed(rocks_params))
    missed = [
        (truth[i].shape, truth[i].height_m, float(t_range[i]))
        for i in np.flatnonzero(target)
        if int(i) not in found_set
    ]
    return ExtractionEval(
        n_true=int(target.sum()),
        n_found=int(sum(1 for i in np.flatnonzero(target) if int(i) in found_set)),
        n_extracted=int(in_range.sum()),
        n_correct=int(np.sum(in_range & (idx >= 0))),
        rms_m=rms,
        type_match=types,
        range_m=ranges,
        missed=missed,
        shapes=shapes,
        well_observed=well,
    )


@dataclass(frozen=True)
class MatchEval:
    """One site pair: matches, how many are the same generated rock, and the site-to-site position error."""

    site_a: int
    site_b: int
    separation_m: float  # true horizontal distance between the two sites
    n_matches: int
    n_correct: int
    position_error_m: float  # |b's position from a's truth and the rock transform - b's true position|
    odometry_error_m: float  # the same from the onboard estimates alone

    @property
    def error_pct(self) -> float:
        return 100.0 * self.position_error_m / self.separation_m


def evaluate_match(a: SiteSurvey, b: SiteSurvey, match: SiteMatch, terrain: Terrain) -> MatchEval:
    """Correct matches (both rocks associated with the same generated rock) and the site-to-site error.

    The match maps b's estimated frame into a's; a's estimated frame maps onto the true world by the truth, so
    b's position through a's truth and the match is compared with b's true position.
    """
    ia, ib = associate(a, terrain.rocks), associate(b, terrain.rocks)
    correct = sum(1 for i, j in match.pairs if ia[i] >= 0 and ia[i] == ib[j])
    Wa = a.estimated_to_true()
    eb = b.T_world_rover_onboard[:3, 3]
    via_rocks = match.transform.apply(eb[None])[0]
    true_b = b.T_world_rover_true[:3, 3]
    pos = Wa[:3, :3] @ via_rocks + Wa[:3, 3]
    odo = Wa[:3, :3] @ eb + Wa[:3, 3]
    sep = float(np.linalg.norm(true_b[:2] - a.T_world_rover_true[:2, 3]))
    return MatchEval(
        a.index,
        b.index,
        sep,
        len(match.pairs),
        correct,
        float(np.linalg.norm(pos - true_b)),
        float(np.linalg.norm(odo - true_b)),
    )


@dataclass(frozen=True)
class ChainEval:
    """Position errors (m) of every site: dead reckoning, VO (onboard), adjusted (final and at addition)."""

    dead_reckoning: np.ndarray
    vo: np.ndarray
    adjusted: np.ndarray
    adjusted_incremental: np.ndarray


def evaluate_chain(sites: list[SiteSurvey], chain: SiteChain) -> ChainEval:
    truth = np.array([s.T_world_rover_true[:3, 3] for s in sites])
    dr = np.array([s.T_world_rover_dr[:3, 3] for s in sites])
    vo = np.array([s.T_world_rover_onboard[:3, 3] for s in sites])
    adj = np.array([c.adjusted_xyz_m for c in chain.sites])
    inc = np.array([c.at_addition for c in chain.sites])

    def err(p: np.ndarray) -> np.ndarray:
        return np.linalg.norm(p - truth, axis=1)

    return ChainEval(err(dr), err(vo), err(adj), err(inc))


def correction_to_truth(site: SiteSurvey) -> Pose4:
    """The :class:`Pose4` part (yaw, translation) of :meth:`SiteSurvey.estimated_to_true` (evaluation only)."""
    W = site.estimated_to_true()
    return Pose4(W[:3, 3].copy(), math.atan2(W[1, 0], W[0, 0]))
