"""The global localiser's matching and refusal on synthetic local maps cut from a synthetic orbital map."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from nav.globalloc import GlobalLocParams, OrbitalLocalizer, OrbitalMap, Raster
from nav.globalloc.localizer import GlobalLocResult
from nav.globalloc.localmap import LocalPoints
from nav.protocols import GlobalLocalizer, PluginContractError, check_globalloc_result

PX = 0.25
COV = np.diag([12.0**2, 12.0**2, math.radians(1.75) ** 2])


def orbital(values: np.ndarray) -> OrbitalMap:
    h, w = values.shape
    img = Raster(values.astype(np.float32), -0.5 * (w - 1) * PX, -0.5 * (h - 1) * PX, PX)
    dem = Raster(np.zeros((h // 4, w // 4), np.float32), img.x0_m, img.y0_m, 4 * PX)
    return OrbitalMap(img, dem, np.array([0.5, 0.0, -0.86]), 0.25, 0.0, 0.0, 0.5)


def textured(seed: int, n: int = 400) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return 1000.0 + 60.0 * gaussian_filter(rng.normal(size=(n, n)), 1.2)


def local_points(omap: OrbitalMap, truth: np.ndarray, rng: np.random.Generator, noise: float = 0.02) -> LocalPoints:
    """Points on a ring 3-24 m around ``truth`` in the prior-yaw level frame, grey from the map (plus noise)."""
    r = np.sqrt(rng.uniform(3.0**2, 24.0**2, 100_000))
    a = rng.uniform(-math.pi, math.pi, r.size)
    xy_site = np.c_[r * np.cos(a), r * np.sin(a)]
    grey = omap.image.sample(truth[0] + xy_site[:, 0], truth[1] + xy_site[:, 1])
    grey = grey / np.nanmedian(grey) * (1 + noise * rng.normal(size=grey.size))
    return LocalPoints(np.c_[xy_site, np.zeros(len(r))], grey)


def test_fix_on_textured_map_is_within_a_pixel():
    omap = orbital(textured(0))
    rng = np.random.default_rng(1)
    truth = np.array([3.3, -2.1, 0.4])
    pts = local_points(omap, truth, rng)
    prior = np.array([truth[0] + 20.0, truth[1] - 15.0, truth[2]])
    res = OrbitalLocalizer().match(pts, prior, COV, omap)
    assert res.status == "ok", res.reason
    assert np.hypot(*(res.xy_yaw[:2] - truth[:2])) < 0.15
    assert res.covariance[0, 0] > 0 and res.covariance[1, 1] > 0
    check_globalloc_result(res)


def test_refuses_featureless_map():
    """Orbital image of pure sensor noise, local map of independent noise: nothing to match, so no fix."""
    rng = np.random.default_rng(2)
    omap = orbital(1000.0 + 10.0 * rng.normal(size=(400, 400)))
    pts = LocalPoints(np.c_[rng.uniform(-24, 24, (100_000, 2)), np.zeros(100_000)], 1 + 0.01 * rng.normal(size=100_000))
    res = OrbitalLocalizer().match(pts, np.array([0.0, 0.0, 0.0]), COV, omap)
    assert res.status != "ok"


def test_refuses_periodic_stripes():
    """Straight dunes: the local map fits every crest along the stripes equally well."""
    n = 400
    x = (np.arange(n) - n / 2) * PX
    stripes = 1000.0 + 60.0 * np.sin(2 * math.pi * x / 6.0)[None, :].repeat(n, axis=0)
    rng = np.random.default_rng(3)
    omap = orbital(stripes + rng.normal(0, 3.0, (n, n)))
    truth = np.array([1.0, 2.0, 0.0])
    res = OrbitalLocalizer().match(local_points(omap, truth, rng), np.array([10.0, 5.0, 0.0]), COV, omap)
    assert res.status != "ok"


def test_refuses_when_prior_region_is_off_the_map():
    omap = orbital(textured(4, 200))
    rng = np.random.default_rng(5)
    pts = local_points(omap, np.zeros(3), rng)
    res = OrbitalLocalizer().match(pts, np.array([500.0, 500.0, 0.0]), COV, omap)
    assert res.status != "ok"


def test_builtin_has_the_protocol_and_the_check_rejects_bad_results():
    assert isinstance(OrbitalLocalizer(GlobalLocParams()), GlobalLocalizer)
    with pytest.raises(PluginContractError, match="xy_yaw"):
        check_globalloc_result(GlobalLocResult("ok", "", np.array([1.0, np.nan, 0.0]), np.eye(3)))
    with pytest.raises(PluginContractError, match="covariance"):
        check_globalloc_result(GlobalLocResult("ok", "", np.zeros(3), -np.eye(3)))
    check_globalloc_result(GlobalLocResult("refused", "nothing seen"))
