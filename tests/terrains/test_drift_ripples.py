"""Drift ripples (``TerrainRecipe.drift_ripples``, the Purgatory ripple): shape, drift material, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from terrains import DriftRippleSpec, Material, TerrainRecipe, synthesize
from terrains.synth import drift_ripple_m


def _recipe(**ripple) -> TerrainRecipe:
    spec = {"x_m": 0.5, "y_m": 0.0, "height_m": 0.3, "width_m": 3.0, "length_m": 4.0} | ripple
    return TerrainRecipe(size_m=(8.0, 6.0), cell_size_m=0.04, drift_ripples=[spec])


def test_profile_height_width_and_steepest_flank():
    xs, ys = np.linspace(-3.0, 3.0, 601), np.array([0.0])
    h = drift_ripple_m(xs, ys, 0.5, 0.0, 0.3, 3.0, 10.0, 0.0)[0]
    assert h.max() == pytest.approx(0.3, abs=1e-4) and xs[np.argmax(h)] == pytest.approx(0.5, abs=0.01)
    assert (h[np.abs(xs - 0.5) >= 1.5] < 1e-12).all()  # nothing beyond half a width of the crest
    steepest = math.degrees(math.atan(np.abs(np.gradient(h, xs)).max()))
    assert steepest == pytest.approx(math.degrees(math.atan(math.pi * 0.3 / 3.0)), abs=0.3)


def test_crest_runs_normal_to_the_azimuth_and_its_ends_taper():
    xs = ys = np.linspace(-4.0, 4.0, 201)
    h = drift_ripple_m(xs, ys, 0.0, 0.0, 0.3, 2.0, 4.0, 90.0)  # section along y, crest along x
    i0 = np.argmin(np.abs(ys))
    assert h[i0, np.argmin(np.abs(xs))] == pytest.approx(0.3)
    assert h[i0, np.argmin(np.abs(xs - 1.0))] == pytest.approx(0.3)  # inside the crest length, before the taper
    assert h[i0, np.argmin(np.abs(xs - 2.0))] == pytest.approx(0.0, abs=1e-9)  # the end (length / 2)
    assert h[np.argmin(np.abs(ys - 0.5)), np.argmin(np.abs(xs))] < 0.3  # across the crest it falls off


def test_thick_drift_is_drift_material_and_its_thin_margins_the_ground():
    t = synthesize(_recipe(drift_min_thickness_m=0.05), seed=3)
    flat = synthesize(TerrainRecipe(size_m=(8.0, 6.0), cell_size_m=0.04), seed=3)
    thickness = t.heights_m - flat.heights_m  # same seed: same roughness, the ripple added
    drift = t.materials == Material.DRIFT
    assert drift.any() and (thickness[drift] >= 0.05 - 1e-9).all()
    assert (t.materials[(thickness > 1e-6) & (thickness < 0.05)] == Material.SAND).all()
    again = synthesize(_recipe(drift_min_thickness_m=0.05), seed=3)
    assert again.heights_m.tobytes() == t.heights_m.tobytes() and again.materials.tobytes() == t.materials.tobytes()


def test_bad_drift_ripples_are_rejected_naming_the_field():
    with pytest.raises(ValidationError, match="drift_ripples.0: crest centre"):
        _recipe(x_m=20.0)
    with pytest.raises(ValidationError, match="height_m"):
        DriftRippleSpec(x_m=0.0, y_m=0.0, height_m=-0.1)
    assert TerrainRecipe().drift_ripples == []
