"""Height layers, materials, and determinism of ``synthesize``."""

from __future__ import annotations

import numpy as np
import pytest

from terrains import (
    CraterSpec,
    Material,
    MaterialSpec,
    RippleSpec,
    RockSpec,
    RoughnessSpec,
    SlopeSpec,
    TerrainRecipe,
    synthesize,
)
from terrains._noise import layer_rng
from terrains.synth import Layer, crater_profile_m, fbm_noise_m, ripple_profile, ripples_m

FLAT = RoughnessSpec(rms_m=0.0)
NO_ROCKS = RockSpec(cover_fraction=0.0)


def _busy_recipe() -> TerrainRecipe:
    return TerrainRecipe(
        size_m=(12.0, 10.0),
        cell_size_m=0.1,
        slope=SlopeSpec(slope_deg=12.0, azimuth_deg=40.0),
        roughness=RoughnessSpec(rms_m=0.05),
        ripples=RippleSpec(amplitude_m=0.1, wavelength_m=2.0, sinuosity=0.3),
        craters=[CraterSpec(center_xy_m=(3.0, 1.0), diameter_m=6.0)],
        rocks=RockSpec(cover_fraction=0.1),
        explicit_rocks=[{"name": "Wopmay", "x_m": -3.0, "y_m": 2.0, "length_m": 1.5, "width_m": 0.9, "height_m": 0.6}],
        material=MaterialSpec(kind="patches", outcrop_slope_deg=30.0),
    )


def test_same_seed_gives_identical_bytes() -> None:
    a, b = synthesize(_busy_recipe(), 7), synthesize(_busy_recipe(), 7)
    assert a.heights_m.tobytes() == b.heights_m.tobytes()
    assert a.materials.tobytes() == b.materials.tobytes()
    assert a.rocks == b.rocks
    assert len(a.rocks) > 5


def test_different_seed_differs() -> None:
    a, b = synthesize(_busy_recipe(), 7), synthesize(_busy_recipe(), 8)
    assert not np.array_equal(a.heights_m, b.heights_m)
    assert not np.array_equal(a.materials, b.materials)
    assert [(r.x_m, r.y_m) for r in a.rocks] != [(r.x_m, r.y_m) for r in b.rocks]


def test_adding_a_layer_leaves_the_others_alone() -> None:
    base = _busy_recipe().model_copy(update={"ripples": None})
    with_ripples = _busy_recipe()
    a, b = synthesize(base, 3), synthesize(with_ripples, 3)
    rp = with_ripples.ripples
    assert rp is not None
    expected = ripples_m(
        a.xs_m,
        a.ys_m,
        rp.amplitude_m,
        rp.wavelength_m,
        rp.azimuth_deg,
        rp.sharpness,
        rp.sinuosity,
        layer_rng(3, Layer.RIPPLES),
    )
    np.testing.assert_allclose(b.heights_m - a.heights_m, expected, atol=1e-12)
    assert [(r.x_m, r.y_m, r.shape, r.height_m) for r in a.rocks] == [
        (r.x_m, r.y_m, r.shape, r.height_m) for r in b.rocks
    ]


@pytest.mark.parametrize(("slope_deg", "azimuth_deg"), [(0.0, 0.0), (17.0, 0.0), (20.0, 135.0), (31.0, -60.0)])
def test_planar_slope_has_the_commanded_slope_and_azimuth(slope_deg: float, azimuth_deg: float) -> None:
    recipe = TerrainRecipe(
        size_m=(8, 6),
        cell_size_m=0.1,
        slope=SlopeSpec(slope_deg=slope_deg, azimuth_deg=azimuth_deg),
        roughness=FLAT,
        rocks=NO_ROCKS,
        base_height_m=1.25,
    )
    t = synthesize(recipe, 0)
    gx, gy = np.meshgrid(t.xs_m, t.ys_m)
    design = np.column_stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
    (a, b, c), *_ = np.linalg.lstsq(design, t.heights_m.ravel(), rcond=None)
    assert np.degrees(np.arctan(np.hypot(a, b))) == pytest.approx(slope_deg, abs=1e-9)
    assert c == pytest.approx(1.25, abs=1e-9)
    if slope_deg > 0:
        fitted_az = np.degrees(np.arctan2(b, a))
        assert (fitted_az - azimuth_deg + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(t.slope_deg_at(gx, gy), slope_deg, atol=1e-9)


@pytest.mark.parametrize(("diameter_m", "d_over_d", "flat"), [(20.0, 0.2, 0.0), (20.0, 0.12, 0.3), (8.0, 0.25, 0.0)])
def test_crater_depth_and_rim(diameter_m: float, d_over_d: float, flat: float) -> None:
    """Eagle-sized bowls: rim-to-floor depth is d/D x D, the rim stands above the surroundings."""
    crater = CraterSpec(diameter_m=diameter_m, depth_to_diameter=d_over_d, rim_height_frac=0.036, floor_flatness=flat)
    recipe = TerrainRecipe(size_m=(40, 40), cell_size_m=0.1, craters=[crater], roughness=FLAT, rocks=NO_ROCKS)
    t = synthesize(recipe, 0)
    radius = diameter_m / 2
    r = np.hypot(*np.meshgrid(t.xs_m, t.ys_m))
    floor, rim = t.heights_m.min(), t.heights_m[np.abs(r - radius) < 0.05].max()
    assert rim - floor == pytest.approx(d_over_d * diameter_m, rel=1e-3)
    assert rim == pytest.approx(0.036 * diameter_m, rel=1e-3)
    assert t.height_at(0.0, 0.0) == pytest.approx(floor, abs=1e-12)
    outside = t.heights_m[r > 1.5 * radius]
    assert rim > outside.max() > 0.0  # ejecta raised, but below the rim
    assert t.heights_m[r > 2.5 * radius].max() < 0.1 * rim  # (r/R)^-3 ejecta falloff
    if flat > 0:
        assert np.ptp(t.heights_m[r < 0.9 * flat * radius]) < 1e-12


def test_crater_profile_is_continuous_and_smooth_at_the_rim() -> None:
    r = np.linspace(0.0, 30.0, 30001)
    z = crater_profile_m(r, 20.0, 0.2, 0.036, 0.1, 0.0)
    assert np.max(np.abs(np.diff(z))) < 2e-3  # no jumps on a 1 mm radial step
    assert np.argmax(z) == pytest.approx(10000, abs=2)  # crest at r = R


def test_large_crater_window_sits_on_the_wall() -> None:
    """An Endurance-sized bowl (130 m) seen through a 10 m patch on its inner wall slopes toward the
    centre."""
    crater = CraterSpec(center_xy_m=(-45.0, 0.0), diameter_m=130.0, depth_to_diameter=0.15)
    t = synthesize(TerrainRecipe(size_m=(10, 10), cell_size_m=0.1, craters=[crater], roughness=FLAT, rocks=NO_ROCKS), 0)
    assert t.heights_m[:, -1].mean() > t.heights_m[:, 0].mean()
    assert 10.0 < float(t.slope_deg_at(0.0, 0.0)) < 40.0


def test_fbm_has_exact_rms_and_zero_mean() -> None:
    z = fbm_noise_m((200, 300), 0.05, 0.03, 1.0, 5, 0.7, np.random.default_rng(0))
    assert z.std() == pytest.approx(0.03, rel=1e-9)
    assert abs(z.mean()) < 1e-12


@pytest.mark.parametrize("correlation_length_m", [50.0, 1000.0])
def test_scales_beyond_the_patch_give_smooth_relief_not_amplified_rounding_noise(
    correlation_length_m: float,
) -> None:
    z = fbm_noise_m((100, 100), 0.05, 0.02, correlation_length_m, 1, 0.8, np.random.default_rng(0))
    assert z.std() == pytest.approx(0.02)
    assert np.abs(np.diff(z, axis=0)).max() < 0.2 * 0.02  # white noise would jump by ~4 x rms


def test_rougher_hurst_has_more_short_scale_relief() -> None:
    smooth = fbm_noise_m((256, 256), 0.05, 0.03, 2.0, 8, 1.0, np.random.default_rng(0))
    rough = fbm_noise_m((256, 256), 0.05, 0.03, 2.0, 8, 0.0, np.random.default_rng(0))
    assert np.abs(np.diff(rough, axis=1)).mean() > 2.0 * np.abs(np.diff(smooth, axis=1)).mean()


def test_ripples_amplitude_wavelength_and_asymmetry() -> None:
    ripple = RippleSpec(amplitude_m=0.2, wavelength_m=2.0, azimuth_deg=0.0, sharpness=0.8, sinuosity=0.0)
    t = synthesize(TerrainRecipe(size_m=(20, 4), cell_size_m=0.02, ripples=ripple, roughness=FLAT, rocks=NO_ROCKS), 0)
    row = t.heights_m[t.nrow // 2]
    assert np.ptp(row) == pytest.approx(0.4, rel=0.01)
    np.testing.assert_allclose(t.heights_m, np.broadcast_to(row, t.heights_m.shape))  # crests run north-south
    spectrum = np.abs(np.fft.rfft(row - row.mean()))
    freq = np.fft.rfftfreq(row.size, d=0.02)
    assert freq[np.argmax(spectrum)] == pytest.approx(0.5, abs=0.06)
    grad = np.diff(row) / 0.02
    assert -grad.min() > 1.5 * grad.max()  # lee faces (toward +x, the azimuth) are steeper than stoss slopes


def test_ripple_profile_range_and_crest() -> None:
    phase = np.linspace(0, 1, 10001)
    for sharpness in (0.0, 0.5, 1.0):
        p = ripple_profile(phase, sharpness)
        assert p.min() == pytest.approx(-1.0) and p.max() == pytest.approx(1.0)
        assert phase[np.argmax(p)] == pytest.approx(0.5 + 0.3 * sharpness, abs=1e-3)


def test_patch_materials_hit_the_requested_fractions() -> None:
    spec = MaterialSpec(kind="patches", bedrock_fraction=0.35, mixed_fraction=0.15, patch_scale_m=2.0)
    t = synthesize(TerrainRecipe(size_m=(20, 20), cell_size_m=0.1, material=spec, rocks=NO_ROCKS), 4)
    fractions = np.bincount(t.materials.ravel(), minlength=3) / t.materials.size
    assert fractions[Material.BEDROCK] == pytest.approx(0.35, abs=1e-4)
    assert fractions[Material.MIXED] == pytest.approx(0.15, abs=1e-4)
    assert t.material_at(t.xs_m[5], t.ys_m[7]) == t.materials[7, 5]


@pytest.mark.parametrize("kind", ["sand", "bedrock", "mixed"])
def test_uniform_materials(kind: str) -> None:
    t = synthesize(TerrainRecipe(size_m=(4, 4), cell_size_m=0.1, material=MaterialSpec(kind=kind), rocks=NO_ROCKS), 0)
    assert np.unique(t.materials).tolist() == [int(Material[kind.upper()])]


def test_steep_crater_walls_become_outcrop() -> None:
    crater = CraterSpec(diameter_m=20.0, depth_to_diameter=0.2)
    recipe = TerrainRecipe(
        size_m=(30, 30),
        cell_size_m=0.1,
        craters=[crater],
        roughness=FLAT,
        rocks=NO_ROCKS,
        material=MaterialSpec(kind="sand", outcrop_slope_deg=25.0),
    )
    t = synthesize(recipe, 0)
    assert t.material_at(0.0, 0.0) == Material.SAND  # floor
    assert t.material_at(8.0, 0.0) == Material.BEDROCK  # upper wall
    assert t.material_at(14.0, 0.0) == Material.SAND  # ejecta apron
    assert np.all(t.materials[t.slope_deg_at(*np.meshgrid(t.xs_m, t.ys_m)) > 27.0] == Material.BEDROCK)


def test_40m_patch_at_5cm_synthesises_deterministically() -> None:
    """The scenarios' largest whole-site recipe: same seed, same heights; another seed differs. (Speed is a
    benchmark matter, not a timed test: see ``rover-sim bench traverse`` for synthesis cost at scale.)"""
    recipe = TerrainRecipe(
        size_m=(40, 40),
        cell_size_m=0.05,
        slope=SlopeSpec(slope_deg=10),
        ripples=RippleSpec(sinuosity=0.2),
        craters=[CraterSpec(diameter_m=20.0)],
        material=MaterialSpec(kind="patches", outcrop_slope_deg=25),
        rocks=RockSpec(cover_fraction=0.07),
    )
    a, b, c = synthesize(recipe, 1), synthesize(recipe, 1), synthesize(recipe, 2)
    assert a.heights_m.shape == (801, 801)
    assert np.array_equal(a.heights_m, b.heights_m)
    assert not np.array_equal(a.heights_m, c.heights_m)


def test_negative_seed_is_rejected() -> None:
    with pytest.raises(ValueError, match="non-negative"):
        synthesize(TerrainRecipe(size_m=(2, 2), cell_size_m=0.1), -1)
