"""Self-calibration of the stereo range bias from rocks seen at two sites (nav/rocks/range_bias.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav.rocks import MatchParams, Pose4, SiteRocks, match_rocks
from nav.rocks.range_bias import correct_rock, correct_rocks, corrected_points, estimate_inverse_range_bias
from tests.nav.test_rocks import observe, rock_field

BETA = -1.35e-3  # 1/m: a toe-in of -0.27 mrad on a 20 cm baseline (bench rocks' flight draw): +0.8 m at 25 m


def biased(site: SiteRocks, beta: float) -> SiteRocks:
    """``site`` as a stereo pair with inverse-range bias ``beta`` sees it (the correction run backwards)."""
    return SiteRocks([correct_rock(r, site.sensor_xyz_m, -beta) for r in site.rocks], site.sensor_xyz_m)


def test_corrected_points_invert_the_bias_along_the_line_of_sight() -> None:
    s = np.array([1.0, 2.0, 1.5])
    p = s + np.array([[3.0, 4.0, -1.0], [20.0, -5.0, -1.5]])
    seen = corrected_points(p, s, -BETA)  # biased
    assert np.linalg.norm(seen[1] - s) - np.linalg.norm(p[1] - s) == pytest.approx(0.61, abs=0.02)
    np.testing.assert_allclose(corrected_points(seen, s, BETA), p, atol=1e-9)
    unit = (p - s) / np.linalg.norm(p - s, axis=1)[:, None]  # moved along the ray only
    np.testing.assert_allclose(np.cross(seen - s, unit), 0.0, atol=1e-9)


@pytest.mark.parametrize("beta", [BETA, -BETA / 2])
def test_bias_is_recovered_from_two_sites_and_the_rocks_move_back(beta: float) -> None:
    """Two sites 15 m apart see a rock field with an inverse-range bias (and k r^2 range noise, size noise, 10 %
    missed rocks); matched as the chain matches them, the fit recovers the bias within 0.25e-3 1/m (a fifth of
    the flight draw), and the corrected rocks sit nearer their true places than the biased ones beyond 15 m."""
    field = rock_field(250, 40.0, seed=11)
    drift = Pose4(np.array([0.3, -0.2, 0.02]), math.radians(1.0))
    a_true = observe(field, (0.0, 0.0), Pose4(), seed=12)
    b_true = observe(field, (12.0, 9.0), drift.inverse(), seed=13)
    a, b = biased(a_true, beta), biased(b_true, beta)
    m = match_rocks(a, b, Pose4(), MatchParams())
    assert m.ok
    fit = estimate_inverse_range_bias([a, b], {(0, 1): m})
    assert fit is not None and abs(fit.beta_per_m - beta) < 0.25e-3
    assert fit.cost_at_fit < fit.cost_at_zero
    fixed = correct_rocks(a, fit.beta_per_m)
    far = np.linalg.norm(a_true.positions[:, :2] - a.sensor_xyz_m[:2], axis=1) > 15.0
    before = np.linalg.norm(a.positions - a_true.positions, axis=1)[far]
    after = np.linalg.norm(fixed.positions - a_true.positions, axis=1)[far]
    assert np.median(after) < 0.5 * np.median(before)


def test_unbiased_sites_fit_no_bias() -> None:
    field = rock_field(250, 40.0, seed=21)
    a = observe(field, (0.0, 0.0), Pose4(), seed=22)
    b = observe(field, (-10.0, 11.0), Pose4(), seed=23)
    m = match_rocks(a, b, Pose4(), MatchParams())
    fit = estimate_inverse_range_bias([a, b], {(0, 1): m})
    assert fit is not None and abs(fit.beta_per_m) < 0.25e-3
    assert estimate_inverse_range_bias([a, b], {}) is None
