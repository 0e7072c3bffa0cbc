"""DIMES estimator on synthetic descent images (pure: no MuJoCo, no rendering).

A textured ground map is imaged by warping it with each camera's known ground-to-image homography, so every
image pair is related by a known plane homography and the true displacement and velocity are known exactly.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from scipy import ndimage

from nav.camera import PinholeCamera
from nav.dimes import (
    DescentImage,
    DimesParams,
    agreeing_group,
    apply_homography,
    estimate_velocity,
    fit_altitudes,
    ground_offset_m,
    ground_to_image,
    match_feature,
    pair_velocity,
    plane_homography,
    pyramid,
    search_window_mask,
    select_features,
)
from nav.geometry import so3_exp

CAM = PinholeCamera.from_fov("descent", 256, 256, 45.0)
NADIR = np.diag([1.0, -1.0, -1.0])  # camera looking straight down, image x east, image y south
MAP_M_PER_PX = 2.0
MAP_HALF_M = 2000.0


@pytest.fixture(scope="module")
def ground_map() -> np.ndarray:
    """Grey-level ground albedo map (4 km square at 2 m/px): mottling at 10-200 m scales, 0..255."""
    rng = np.random.default_rng(4)
    n = int(2 * MAP_HALF_M / MAP_M_PER_PX)
    out = np.zeros((n, n))
    for sigma_m, amp in ((10.0, 1.0), (40.0, 1.5), (200.0, 2.0)):
        spectrum = ndimage.fourier_gaussian(np.fft.rfft2(rng.standard_normal((n, n))), sigma_m / MAP_M_PER_PX, n=n)
        f = np.fft.irfft2(spectrum, s=(n, n))  # periodic Gaussian blur
        out += amp * f / f.std()
    return (110.0 + 12.0 * out).astype(np.float32)


def attitude(tilt_x_deg: float, tilt_y_deg: float, yaw_deg: float) -> np.ndarray:
    yaw = math.radians(yaw_deg)
    Rz = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    return so3_exp(np.radians([tilt_x_deg, tilt_y_deg, 0.0])) @ Rz @ NADIR


def view(ground_map: np.ndarray, R: np.ndarray, centre_m: np.ndarray, noise_seed: int = 0) -> np.ndarray:
    """The camera image of the ground map (warp by the ground-to-image homography), with read noise, uint8."""
    map_to_ground = np.array([[MAP_M_PER_PX, 0.0, -MAP_HALF_M], [0.0, MAP_M_PER_PX, -MAP_HALF_M], [0.0, 0.0, 1.0]])
    H = ground_to_image(CAM, R, centre_m) @ map_to_ground
    img = cv2.warpPerspective(ground_map, H, (CAM.width_px, CAM.height_px), flags=cv2.INTER_LINEAR)
    img = img + np.random.default_rng(noise_seed).normal(0.0, 0.5, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def synthetic_descent(
    ground_map: np.ndarray,
    v0_mps=(12.0, -7.0),
    accel_mps2=(0.3, 0.2),
    attitudes_deg=((2.0, -1.0, 20.0), (-1.5, 2.5, 31.0), (1.0, 0.5, 40.0)),
    altitudes_m=(2000.0, 1700.0, 1400.0),
    dt_s: float = 4.0,
    imu_accel_mps2=None,
) -> list[DescentImage]:
    """Three frames with exactly known motion: constant acceleration, IMU consistent unless told otherwise."""
    v0, a = np.array([*v0_mps, -75.0]), np.array([*accel_mps2, 0.0])
    a_imu = a if imu_accel_mps2 is None else np.array([*imu_accel_mps2, 0.0])
    frames = []
    for k, (att, h) in enumerate(zip(attitudes_deg, altitudes_m, strict=True)):
        t = k * dt_s
        xy = np.array([-60.0, 40.0]) + v0[:2] * t + 0.5 * a[:2] * t * t
        R = attitude(*att)
        frames.append(
            DescentImage(
                t_s=t,
                image=view(ground_map, R, np.array([xy[0], xy[1], h]), noise_seed=k),
                camera=CAM,
                R_world_cam=R,
                altitude_m=h,
                imu_delta_v_mps=a_imu * t,
                imu_delta_p_m=0.5 * a_imu * t * t,
            )
        )
    return frames


# ---------------------------------------------------------------------------------------------- geometry


def test_plane_homography_maps_ground_points_between_views():
    R_i, R_j = attitude(3.0, -2.0, 10.0), attitude(-1.0, 1.0, 25.0)
    d = np.array([40.0, -25.0])
    H = plane_homography(CAM, R_i, 2000.0, CAM, R_j, 1700.0, d)
    ground = np.c_[np.random.default_rng(0).uniform(-500, 500, (20, 2)), np.zeros(20)]
    uv_i = CAM.project((ground - [0.0, 0.0, 2000.0]) @ R_i)
    uv_j = CAM.project((ground - [d[0], d[1], 1700.0]) @ R_j)
    np.testing.assert_allclose(apply_homography(H, uv_i), uv_j, atol=1e-6)
    # ground_offset_m inverts the projection
    np.testing.assert_allclose(ground_offset_m(CAM, R_i, 2000.0, uv_i), ground[:, :2], atol=1e-6)


def test_fit_altitudes_is_exact_on_consistent_data_and_averages_noise(ground_map):
    frames = synthetic_descent(ground_map)
    np.testing.assert_allclose(fit_altitudes(frames), [2000.0, 1700.0, 1400.0], atol=1e-9)
    noisy = [
        DescentImage(**{**f.__dict__, "altitude_m": f.altitude_m + e}) for f, e in zip(frames, (6, -6, 6), strict=True)
    ]
    fitted = fit_altitudes(noisy)
    assert np.abs(fitted - [2000.0, 1700.0, 1400.0]).max() < 6.0 * 0.7


# ---------------------------------------------------------------------------------------------- matching


def test_warped_template_match_recovers_a_known_homography(ground_map):
    """Warp a textured image by a known homography (rotation, scale, perspective): the match lands where it
    maps each feature, to a tenth of a pixel."""
    R_i, R_j = attitude(2.0, 1.0, 0.0), attitude(-2.0, 3.0, 14.0)
    d = np.array([55.0, 30.0])
    img_i = view(ground_map, R_i, np.array([0.0, 0.0, 1900.0]))
    img_j = view(ground_map, R_j, np.array([d[0], d[1], 1600.0]), noise_seed=1)
    H_true = plane_homography(CAM, R_i, 1900.0, CAM, R_j, 1600.0, d)
    H_prior = plane_homography(CAM, R_i, 1900.0, CAM, R_j, 1600.0, np.zeros(2))  # drift unknown
    params = DimesParams()
    mask = search_window_mask(img_i.shape, H_prior, img_j.shape, 8, 50)
    uv, interest = select_features(img_i, mask, params)
    assert len(uv) == 2 and np.all(interest >= params.min_interest)
    pyr_i, pyr_j = pyramid(img_i, 2), pyramid(img_j, 2)
    for p in uv:
        uv_j, corr, ratio, curv, reason = match_feature(pyr_i, pyr_j, p, H_prior, 30.0, params)
        assert reason == "", reason
        assert corr > 0.9 and ratio < params.max_second_peak_ratio and curv > params.min_peak_curvature
        np.testing.assert_allclose(uv_j, apply_homography(H_true, p)[0], atol=0.35)


def test_pair_velocity_recovers_the_displacement(ground_map):
    frames = synthetic_descent(ground_map, accel_mps2=(0.0, 0.0))
    pair = pair_velocity(frames, 0, 1, np.array([2000.0, 1700.0, 1400.0]), np.zeros(2), 140.0, DimesParams())
    assert pair.ok, pair.reason
    np.testing.assert_allclose(pair.velocity_mps, [12.0, -7.0], atol=0.3)
    assert len(pair.inliers) == 2


@pytest.mark.parametrize("features", [2, 4])
def test_estimate_recovers_the_velocity_at_the_last_image(ground_map, features):
    frames = synthetic_descent(ground_map)
    result = estimate_velocity(frames, DimesParams(features_per_image=features))
    assert result.valid, result.reason
    v_true = np.array([12.0, -7.0]) + np.array([0.3, 0.2]) * 8.0  # v0 + a t3
    np.testing.assert_allclose(result.velocity_mps, v_true, atol=0.3)
    np.testing.assert_allclose(result.accel_dimes_mps2, [0.3, 0.2], atol=0.1)
    assert result.fire_tirs == (np.linalg.norm(v_true) > DimesParams().tirs_threshold_mps)
    assert all(len(p.matches) == features for p in result.pairs)


def test_strong_wind_and_spin_within_the_search_window(ground_map):
    """30 m/s drift (beyond the 20 m/s winds) and 20 deg of spin per interval are still found."""
    frames = synthetic_descent(
        ground_map, v0_mps=(-21.0, 21.0), accel_mps2=(0.0, 0.0), attitudes_deg=((3, 3, 0), (-3, 2, 20), (0, -3, 40))
    )
    result = estimate_velocity(frames)
    assert result.valid, result.reason
    np.testing.assert_allclose(result.velocity_mps, [-21.0, 21.0], atol=0.4)
    assert result.fire_tirs


# ------------------------------------------------------------------------------------------------ checks


def test_featureless_images_are_rejected_by_the_interest_operator(ground_map):
    frames = synthetic_descent(ground_map)
    rng = np.random.default_rng(1)
    flat = [
        DescentImage(
            **{**f.__dict__, "image": np.clip(np.rint(120 + rng.normal(0, 0.5, (256, 256))), 0, 255).astype(np.uint8)}
        )
        for f in frames
    ]
    result = estimate_velocity(flat)
    assert not result.valid and result.velocity_mps is None and not result.fire_tirs
    assert result.reason == "pair 1-2: no_features"


def test_featureless_images_are_rejected_by_the_correlation_checks_when_features_are_forced(ground_map):
    """With the interest thresholds off, the operator picks noise; the correlation checks must refuse it."""
    frames = synthetic_descent(ground_map)
    rng = np.random.default_rng(2)
    yy, xx = np.mgrid[0:256, 0:256]
    flat = [
        DescentImage(
            **{
                **f.__dict__,
                "image": np.clip(np.rint(100 + 0.1 * xx + rng.normal(0, 0.5, (256, 256))), 0, 255).astype(np.uint8),
            }
        )
        for f in frames
    ]
    forced = DimesParams(min_interest=0.0, min_template_std_grey=0.0, features_per_image=4)
    result = estimate_velocity(flat, forced)
    assert not result.valid and result.velocity_mps is None
    reasons = {m.reason for p in result.pairs for m in p.matches}
    assert reasons and "" not in reasons  # no individual match passed either


def test_inconsistent_imu_acceleration_is_rejected(ground_map):
    """The IMU disagrees with the image-derived acceleration by 1 m/s^2: the final check refuses."""
    frames = synthetic_descent(ground_map, imu_accel_mps2=(1.3, 0.2))
    result = estimate_velocity(frames)
    assert not result.valid and result.reason == "acceleration_check"
    assert np.linalg.norm(result.accel_dimes_mps2 - result.accel_imu_mps2) > DimesParams().max_accel_disagreement_mps2


def test_repeated_texture_is_ambiguous():
    """Ground with a periodic pattern (60 m period, several periods in the search window): equal peaks, rejected."""
    n = int(2 * MAP_HALF_M / MAP_M_PER_PX)
    yy, xx = np.mgrid[0:n, 0:n] * MAP_M_PER_PX
    periodic_map = (128 + 60 * np.sin(2 * np.pi * xx / 60.0) * np.sin(2 * np.pi * yy / 60.0)).astype(np.float32)
    result = estimate_velocity(synthetic_descent(periodic_map, accel_mps2=(0.0, 0.0)))
    assert not result.valid and result.velocity_mps is None
    assert {m.reason for p in result.pairs for m in p.matches} == {"ambiguous_peak"}


def test_agreeing_group_needs_mutual_agreement():
    v = np.array([[10.0, 0.0], [10.5, 0.2], [3.0, 4.0], [10.2, -0.3]])
    assert agreeing_group(v, 1.0) == (0, 1, 3)
    assert len(agreeing_group(np.array([[0.0, 0.0], [5.0, 0.0]]), 2.0)) == 1


def test_params_validation():
    with pytest.raises(ValueError):
        DimesParams(template_px=14)
    with pytest.raises(ValueError):
        DimesParams(features_per_image=1)
