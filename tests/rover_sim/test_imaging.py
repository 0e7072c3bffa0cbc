"""Image formation of the flight profile (rover_sim.render.imaging): noise statistics, exposure, fixed pattern."""

from __future__ import annotations

import numpy as np
import pytest

from rover_sim.render.imaging import (
    DN12_MAX,
    ImageFormation,
    ImagingSpec,
    compand_8bit,
    exposure_scale,
)
from rover_sim.scenario.sensors_spec import SensorsSpec

CLEAN = {"prnu_rel": 0.0, "dsnu_e": 0.0, "vignetting_corner_rel": 0.0, "dust_spots": 0, "gain_mismatch_rel": 0.0}


def test_profiles_select_the_chain():
    assert SensorsSpec(profile="ideal").imaging.model == "ideal"
    assert SensorsSpec(profile="flight").imaging.model == "ccd"
    assert SensorsSpec(profile="flight", imaging={"read_noise_e": 5.0}).imaging.read_noise_e == 5.0


@pytest.mark.parametrize("native_px", [256, 1024])
def test_noise_is_shot_plus_read_noise_of_the_photosites_behind_each_pixel(native_px):
    spec = ImagingSpec(model="ccd", exposure_percentile=100.0, **CLEAN)
    img = ImageFormation(spec, seed=3, binning=1)
    luma = np.full((native_px, native_px), 100.0, dtype=np.float32)
    dn = img.dn12(luma, "navcam_left")
    signal_e = spec.exposure_target_dn / DN12_MAX * spec.full_well_e  # a flat field sits at the target
    sites = (1024 / native_px) ** 2
    expected_dn = np.sqrt(signal_e + spec.read_noise_e**2) / np.sqrt(sites) * DN12_MAX / spec.full_well_e
    if sites == 1:
        expected_dn = np.sqrt(expected_dn**2 + 1.0 / 12.0)  # plus the ADC's rounding
    assert dn.mean() == pytest.approx(spec.exposure_target_dn, abs=0.5)
    assert dn.std() == pytest.approx(expected_dn, rel=0.03)


def test_exposure_puts_the_percentile_at_the_target():
    spec = ImagingSpec(model="ccd")
    rng = np.random.default_rng(0)
    radiance = rng.uniform(0.1, 0.4, (64, 64))
    t = exposure_scale(radiance, spec)
    assert np.percentile(radiance * t, spec.exposure_percentile) * DN12_MAX == pytest.approx(spec.exposure_target_dn)


def test_fixed_pattern_is_seeded_per_camera_and_the_two_cameras_differ():
    spec = ImagingSpec(model="ccd")
    a, b = ImageFormation(spec, 7, 1), ImageFormation(spec, 7, 1)
    fl, fr = a.defects("navcam_left", 256).flat, a.defects("navcam_right", 256).flat
    np.testing.assert_array_equal(fl, b.defects("navcam_left", 256).flat)
    assert np.abs(fl - fr).mean() > 0.005  # gain mismatch, vignetting centre and dust differ
    luma = np.full((256, 256), 120.0, dtype=np.float32)
    np.testing.assert_array_equal(a.form(luma, "navcam_left"), b.form(luma, "navcam_left"))
    assert not np.array_equal(a.form(luma, "navcam_left"), ImageFormation(spec, 8, 1).form(luma, "navcam_left"))


def test_binning_after_the_adc_matches_the_direct_rendering_statistics():
    spec = ImagingSpec(model="ccd", exposure_percentile=100.0, **CLEAN)
    luma = np.full((1024, 1024), 90.0, dtype=np.float32)
    binned = ImageFormation(spec, 1, binning=4).dn12(luma, "navcam_left")
    direct = ImageFormation(spec, 1, binning=1).dn12(luma[:256, :256], "navcam_left")
    assert binned.shape == direct.shape == (256, 256)
    assert binned.std() == pytest.approx(direct.std(), rel=0.05)


def test_square_root_companding():
    dn = np.array([0.0, 1.0, 1023.75, DN12_MAX])
    np.testing.assert_array_equal(compand_8bit(dn, "sqrt"), [0, 4, 128, 255])
    assert np.all(np.diff(compand_8bit(np.arange(DN12_MAX + 1.0), "sqrt").astype(int)) >= 0)
