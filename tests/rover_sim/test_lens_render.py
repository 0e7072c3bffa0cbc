"""Raw images through the true lenses, and onboard rectification with the calibrated models."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nav.camera import transform_points
from nav.epipolar import EpipolarCheck
from nav.rectify import StereoCalibration, epipolar_row_error_px, rectification
from rover_sim.render.cameras import camera_model
from rover_sim.render.renderer import StereoRenderer
from rover_sim.scenario.lens_spec import FLIGHT_DEFAULTS, LensErrorSpec
from rover_sim.scenario.sensors_spec import SensorsSpec
from rover_sim.world.calibration import MastEncoders, RunCalibration, build_true_lens, render_rectified
from tests.rover_sim.test_render import bright_blob_centroid, world_T_rover

pytestmark = pytest.mark.render

SEED = 3
FLIGHT = LensErrorSpec(**FLIGHT_DEFAULTS)
# the same true cameras (mounting, lenses: same seed, same draws), a perfect calibration of them
ZERO_ERRORS = ("camera_rotation_deg", "stereo_rotation_deg", "baseline_mm", "focal_length_pct", "principal_point_px")
EXACT = LensErrorSpec(**{**FLIGHT_DEFAULTS, **dict.fromkeys(ZERO_ERRORS, 0.0), "distortion_residual_pct": 0.0})


@pytest.fixture(scope="module")
def lens_renderer(render_world):
    calib = RunCalibration(FLIGHT, SEED)
    lens = build_true_lens(render_world.sim.model, render_world.sim.data, calib, 256)
    r = StereoRenderer(render_world.sim, lens=lens)
    yield r, calib
    r.close()


def raw_terrain_mask(renderer: StereoRenderer, cam_name: str, pair: str) -> np.ndarray:
    """Terrain pixels of the raw image: the wide segmentation render remapped like the image (no position prior)."""
    sim = renderer.sim
    with renderer.lens.view(renderer.world.model, pair, 256) as px:
        seg = renderer.render_segmentation(cam_name, px)
    mx, my = renderer.lens.views[pair].maps[cam_name]
    raw = cv2.remap(seg.astype(np.float32), mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=-1)
    return raw == sim.model.geom("terrain").id


def near_other_markers(render_world, sim, model, pair: str, radius_px: float = 15.0) -> np.ndarray:
    """Pixels within ``radius_px`` of the other pairs' markers (the navcam also sees the hazcam's disc)."""
    vv, uu = np.indices((model.height_px, model.width_px))
    out = np.zeros((model.height_px, model.width_px), bool)
    for name, p in render_world.markers_xyz.items():
        if not name.startswith(pair):
            uv = project_with(sim, model, p)
            if np.all(np.isfinite(uv)):
                out |= np.hypot(uu - uv[0], vv - uv[1]) < radius_px
    return out


def project_with(sim, model, p_world: np.ndarray) -> np.ndarray:
    T = world_T_rover(sim) @ model.T_rover_cam
    return model.project(transform_points(np.linalg.inv(T), p_world[None]))[0]


@pytest.mark.parametrize("pair", ["hazcam_front", "navcam"])
def test_marker_in_raw_image_where_the_true_model_puts_it(render_world, lens_renderer, pair) -> None:
    renderer, calib = lens_renderer
    sim = render_world.sim
    frame = renderer.render_pair(pair)
    p_world = render_world.markers_xyz[f"{pair}_left"]
    for side, image in (("left", frame.left), ("right", frame.right)):
        name = f"{pair}_{side}"
        true = calib.true_model(camera_model(sim.model, sim.data, name, 256, 256))
        expected = project_with(sim, true, p_world)
        pinhole = project_with(sim, camera_model(sim.model, sim.data, name, 256, 256), p_world)
        assert np.linalg.norm(expected - pinhole) > 1.0, "the lens should move the marker (else the test is void)"
        mask = raw_terrain_mask(renderer, name, pair) & ~near_other_markers(render_world, sim, true, pair)
        found = bright_blob_centroid(image, mask)
        assert np.linalg.norm(found - expected) < 1.0, f"{name}: marker at {found}, true model says {expected}"


@pytest.mark.parametrize("pair", ["hazcam_front", "navcam"])
def test_marker_in_rectified_image_where_the_rectified_model_puts_it(render_world, lens_renderer, pair) -> None:
    renderer, _ = lens_renderer
    sim = render_world.sim
    exact = RunCalibration(EXACT, SEED)  # same seed: the same mounting draws as the renderer's truth
    pins = [camera_model(sim.model, sim.data, f"{pair}_{s}", 256, 256) for s in ("left", "right")]
    calib = StereoCalibration(exact.onboard_model(pins[0]), exact.onboard_model(pins[1]), pins[0])
    rect = rectification(calib)
    left, right, rig = render_rectified(renderer, exact, pair)  # the helper benchmarks use
    assert rig is rect.rig
    images = (left, right)
    p_world = render_world.markers_xyz[f"{pair}_left"]
    for side, image, cam, table in zip(("left", "right"), images, (rect.rig.left, rect.rig.right),
                                       (rect.left_map, rect.right_map), strict=True):  # fmt: skip
        raw_mask = raw_terrain_mask(renderer, f"{pair}_{side}", pair).astype(np.uint8)
        mask = cv2.remap(raw_mask, table[0], table[1], cv2.INTER_NEAREST).astype(bool)
        mask &= ~near_other_markers(render_world, sim, cam, pair)
        expected = project_with(sim, cam, p_world)
        found = bright_blob_centroid(image, mask)
        assert np.linalg.norm(found - expected) < 1.0, f"{cam.name}: marker at {found}, rectified model {expected}"


def matched_corners(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(uv_left, uv_right) of corners tracked left -> right (pyramidal LK, forward-backward check < 0.1 px)."""
    pts = cv2.goodFeaturesToTrack(left, 800, 0.003, 5, blockSize=7)
    fwd, st1, _ = cv2.calcOpticalFlowPyrLK(left, right, pts, None, winSize=(15, 15), maxLevel=3)
    back, st2, _ = cv2.calcOpticalFlowPyrLK(right, left, fwd, None, winSize=(15, 15), maxLevel=3)
    ok = (st1[:, 0] == 1) & (st2[:, 0] == 1) & (np.linalg.norm((back - pts)[:, 0], axis=1) < 0.1)
    return pts[ok, 0].astype(float), fwd[ok, 0].astype(float)


def row_disparity_px(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """|v_right - v_left| of the matched corners."""
    uv_l, uv_r = matched_corners(left, right)
    return np.abs(uv_r[:, 1] - uv_l[:, 1])


# The 0.31-0.32 px navcam draws were diagnosed on calibration seeds 1-8 (truth: seed 3) and on the
# exact calibrations of truth seeds 11-15; the bar is asserted on these other draws, fixed before looking at them.
CALIBRATION_SEEDS = range(101, 109)


@dataclass(frozen=True)
class RowDisparity:
    """Median |row disparity| (px) of one calibration draw: measured on matched corners, predicted from the true
    vs calibrated models at the same corners (the ground-truth epipolar error), and their per-corner difference."""

    measured: float
    predicted: float
    residual: float


def onboard_calibration(pins, truth: RunCalibration, calib: RunCalibration, check: EpipolarCheck | None = None):  # noqa: ANN001, ANN201
    """The onboard calibration of ``pins`` (the true cameras of ``truth``, calibrated with ``calib``'s errors),
    as ``check`` corrected it if given."""
    calib.mount = truth.mount  # the same true cameras, another calibration of them
    onboard = StereoCalibration(calib.onboard_model(pins[0]), calib.onboard_model(pins[1]), pins[0])
    return onboard if check is None else check.calibration(onboard)


def rectified_row_disparity(frame, pins, truth: RunCalibration, calib: RunCalibration,  # noqa: ANN001
                            check: EpipolarCheck | None = None) -> RowDisparity:  # fmt: skip
    onboard = onboard_calibration(pins, truth, calib, check)
    rect = rectification(onboard)
    for table in (rect.left_map, rect.right_map):  # every rectified pixel sees inside its raw image (no black edge)
        assert min(t.min() for t in table) >= -1e-3 and max(t.max() for t in table) <= 255.0 + 1e-3
    uv_l, uv_r = matched_corners(*rect.apply(frame.left, frame.right))
    disparity = uv_l[:, 0] - uv_r[:, 0]
    keep = disparity > 0.5  # a depth for the prediction
    assert keep.sum() > 25
    uv_l, uv_r, disparity = uv_l[keep], uv_r[keep], disparity[keep]
    dv = uv_r[:, 1] - uv_l[:, 1]
    truth_l, truth_r = truth.true_model(pins[0]), truth.true_model(pins[1])
    dv_true = epipolar_row_error_px(rect, onboard, truth_l, truth_r, uv_l, disparity)
    return RowDisparity(float(np.median(np.abs(dv))), float(np.median(np.abs(dv_true))),
                        float(np.median(np.abs(dv - dv_true))))  # fmt: skip


def fitted_check(frame, pins, truth: RunCalibration, calib: RunCalibration) -> EpipolarCheck:  # noqa: ANN001
    """The onboard epipolar check after one pair (``frame``, cameras ``pins``) rectified with ``calib``."""
    onboard = onboard_calibration(pins, truth, calib)
    rect = rectification(onboard)
    check = EpipolarCheck(prior_sigma_rad=np.radians(FLIGHT.stereo_rotation_deg))  # as the Onboard makes it
    check.observe(onboard, rect.rig, *rect.apply(frame.left, frame.right))
    return check


OTHER_SCENE_YAW_DEG = 30.0  # the epipolar check's pair: the rover turned in place, so every camera sees new ground


def other_scene_pair(render_world, renderer, pair: str):  # noqa: ANN001, ANN201
    """``pair`` imaged with the rover turned by ``OTHER_SCENE_YAW_DEG`` (pose only, for rendering; the shared
    world's state is restored): (frame, pins)."""
    sim = render_world.sim
    q0 = sim.data.qpos.copy()
    try:
        w, x, y, z = sim.data.qpos[3:7]
        turned = Rotation.from_euler("z", OTHER_SCENE_YAW_DEG, degrees=True) * Rotation.from_quat([x, y, z, w])
        x, y, z, w = turned.as_quat()
        sim.data.qpos[3:7] = [w, x, y, z]
        mujoco.mj_forward(sim.model, sim.data)
        frame = renderer.render_pair(pair)
        pins = [camera_model(sim.model, sim.data, f"{pair}_{s}", 256, 256) for s in ("left", "right")]
    finally:
        sim.data.qpos[:] = q0
        mujoco.mj_forward(sim.model, sim.data)
    return frame, pins


@dataclass(frozen=True)
class PairRowDisparities:
    flight: list[RowDisparity]  # one per CALIBRATION_SEEDS draw, the ground calibration as drawn
    checked: list[RowDisparity]  # the same, after the onboard epipolar check fitted on another scene
    fitted: list[bool]  # whether that check made a fit (enough corners)
    exact: RowDisparity
    raw_px: float  # median |row disparity| of the raw (unrectified) pair


_ROW_DISPARITIES: dict[str, PairRowDisparities] = {}


def pair_row_disparities(render_world, lens_renderer, pair: str) -> PairRowDisparities:  # noqa: ANN001
    """The held-out draws' row disparities on one true pair (computed once per pair for the two tests below)."""
    if pair not in _ROW_DISPARITIES:
        renderer, truth = lens_renderer
        sim = render_world.sim
        other, other_pins = other_scene_pair(render_world, renderer, pair)
        frame = renderer.render_pair(pair)
        pins = [camera_model(sim.model, sim.data, f"{pair}_{s}", 256, 256) for s in ("left", "right")]
        flight = [rectified_row_disparity(frame, pins, truth, RunCalibration(FLIGHT, s)) for s in CALIBRATION_SEEDS]
        checks = [fitted_check(other, other_pins, truth, RunCalibration(FLIGHT, s)) for s in CALIBRATION_SEEDS]
        checked = [rectified_row_disparity(frame, pins, truth, RunCalibration(FLIGHT, s), c)
                   for s, c in zip(CALIBRATION_SEEDS, checks, strict=True)]  # fmt: skip
        exact = rectified_row_disparity(frame, pins, truth, RunCalibration(EXACT, SEED))
        raw = float(np.median(row_disparity_px(frame.left, frame.right)))
        print(f"{pair}: seeds {list(CALIBRATION_SEEDS)} measured {[round(r.measured, 3) for r in flight]} predicted "
              f"{[round(r.predicted, 3) for r in flight]} residual {[round(r.residual, 3) for r in flight]}; "
              f"after the check (fitted: {[c.correction is not None for c in checks]}) measured "
              f"{[round(r.measured, 3) for r in checked]} predicted {[round(r.predicted, 3) for r in checked]}; "
              f"exact {exact.measured:.3f}, raw {raw:.3f}")  # fmt: skip
        fitted = [c.correction is not None for c in checks]
        _ROW_DISPARITIES[pair] = PairRowDisparities(flight, checked, fitted, exact, raw)
    return _ROW_DISPARITIES[pair]


@pytest.mark.parametrize("pair", ["hazcam_front", "navcam"])
def test_rectification_measured_row_disparity_matches_the_models(render_world, lens_renderer, pair) -> None:
    """Rectified flight pairs (8 held-out calibration draws on one true pair): the row disparity measured on
    matched corners agrees with the ground truth, the row error the true vs calibrated models predict at the same
    corners (``epipolar_row_error_px``), to 0.15 px per corner (median: the matcher's own noise, 0.04-0.10 px on
    the diagnosis draws); an exact calibration gives <= 0.1 px measured and 0 predicted; rectified views hold no
    pixel outside the raw images; the raw navcam pair is clearly worse."""
    rows = pair_row_disparities(render_world, lens_renderer, pair)
    assert rows.exact.measured <= 0.1 and rows.exact.predicted < 1e-6
    assert max(r.residual for r in rows.flight + rows.checked) <= 0.15
    if pair == "navcam":  # the hazcams' mounting draw is small
        assert rows.raw_px > 2.0 * np.median([r.measured for r in rows.flight])


@pytest.mark.parametrize("pair", ["hazcam_front", "navcam"])
def test_rectified_flight_pairs_have_small_row_disparity(render_world, lens_renderer, pair) -> None:
    """Rectification: every flight calibration draw leaves a median row disparity <= 0.3 px on matched corners of
    the rectified pair (8 held-out draws, :data:`CALIBRATION_SEEDS`, on one true pair), measured and as predicted
    from the models, once the onboard epipolar check (``nav.epipolar``) has fitted the relative pitch and roll on
    *another* scene (the rover turned 30 deg). The navcam's ground calibration alone does not meet the bar on
    these draws (draw 104: a 2.3-sigma relative pitch of 0.047 deg, 0.33 px); the check must have fitted there.
    The hazcams are not checked (their 68 px focal length turns the calibration's 0.02 deg into 0.024 px, under
    the resampling's row offsets: ``nav.epipolar.ROW_FLOOR_PX``); their draws meet the bar uncorrected."""
    rows = pair_row_disparities(render_world, lens_renderer, pair)
    assert max(r.measured for r in rows.checked) <= 0.3
    assert max(r.predicted for r in rows.checked) <= 0.3
    if pair == "navcam":
        assert all(rows.fitted)
        assert max(r.measured for r in rows.flight) > 0.3  # what the check is for
        assert np.median([r.predicted for r in rows.checked]) < 0.5 * np.median([r.predicted for r in rows.flight])


def test_flight_profile_fills_lens_errors_and_ideal_has_none() -> None:
    assert SensorsSpec(profile="flight").lens == FLIGHT
    ideal = SensorsSpec(profile="ideal").lens
    assert not ideal.enabled and not ideal.has_mast_error
    with pytest.raises(ValueError, match="sensors.lens.baseline_mm needs sensors.lens.enabled"):
        SensorsSpec(profile="ideal", lens={"baseline_mm": 0.3})


def test_calibration_errors_are_seeded_and_sized() -> None:
    a, b, c = RunCalibration(FLIGHT, 1), RunCalibration(FLIGHT, 1), RunCalibration(FLIGHT, 2)
    np.testing.assert_array_equal(a.errors["navcam_right"].position_m, b.errors["navcam_right"].position_m)
    assert not np.allclose(a.errors["navcam_right"].position_m, c.errors["navcam_right"].position_m)
    many = [RunCalibration(FLIGHT, s).errors["navcam_right"].position_m for s in range(300)]
    assert np.std(many) == pytest.approx(FLIGHT.baseline_mm * 1e-3, rel=0.15)


def test_mast_encoder_error_within_resolution_and_backlash() -> None:
    enc = MastEncoders(FLIGHT, 5)
    bound = 0.5 * FLIGHT.mast_resolution_deg + FLIGHT.mast_backlash_deg
    errs = []
    for pan in (10.0, 30.0, -20.0, -20.0, 5.0):
        true_pan, true_el = enc.true_angles_deg(pan, -15.0)
        errs.append(true_pan - pan)
        assert abs(true_pan - pan) <= bound and abs(true_el + 15.0) <= bound
    assert np.std(errs) > 0.005  # it does move the mast
    assert MastEncoders(LensErrorSpec(), 5).true_angles_deg(10.0, -15.0) == (10.0, -15.0)


FIELD = {
    "name": "lens_probe",
    "terrain": {"size_m": [8, 8], "cell_size_m": 0.05, "rocks": {"cover_fraction": 0.0}},
    "commands": [{"type": "drive", "distance_m": 0.1}],
    "sensors": {"profile": "flight"},
}


def test_flight_world_points_the_mast_with_encoder_error_and_keeps_the_commanded_rig() -> None:
    """The true mast stops off the command by the drawn encoder error; the onboard rig (rectified, from the
    calibrated models) is built at the commanded angles; observations carry raw pairs that Onboard rectifies."""
    from rover_sim.runtime.onboard import Onboard
    from rover_sim.runtime.plugins import make_planner, make_stereo, make_vo
    from rover_sim.scenario.loading import scenario_from_dict
    from rover_sim.world.calibration import cameras_at_pointing
    from rover_sim.world.world import World

    world = World(scenario_from_dict(FIELD))
    try:
        world.point_mast(25.0, -35.0)
        world.sim.step(None, 1000)
        rig = world.calibrate("navcam")
        pan, tilt = np.degrees(world.sim.mast_angles_rad())
        err = world.mast_encoders.last_error_deg
        assert np.abs(err).max() > 1e-3
        assert abs(pan - (25.0 + err[0])) < 0.01 and abs(-tilt - (-35.0 + err[1])) < 0.01
        cmd = cameras_at_pointing(world.sim.model, world.sim.data, ["navcam_left"], 256, 25.0, -35.0)[0]
        # the rectified rig sits at the commanded pointing (up to the calibration's own rotation errors)
        cos = (np.trace(cmd.T_rover_cam[:3, :3].T @ rig.left.T_rover_cam[:3, :3]) - 1) / 2
        assert np.degrees(np.arccos(min(1.0, cos))) < 0.5
        obs = world.observation(("navcam",))
        pair = obs.pair("navcam")
        assert pair.calibration is not None and pair.rig is rig
        nav = world.scenario.nav
        parts = (world.start_pose(), make_vo(nav.vo), make_stereo(nav.stereo), lambda: make_planner(nav.planner))
        onboard = Onboard(*parts, epipolar_check=False)
        rect = onboard.rectified(obs, "navcam")
        assert rect.calibration is None and rect.rig is rig and rect.left_u8.shape == (256, 256)
        assert not np.array_equal(rect.left_u8, pair.left_u8)
        assert onboard.rectified(obs, "navcam") is rect  # cached for the other uses of the same pair
        # with the epipolar check (the default) the first pair fits the relative pitch and roll: the rectified
        # rig turns by a fraction of the stereo calibration's error (0.02 deg per axis), the images change
        events: list[str] = []
        checked = Onboard(*parts, on_event=events.append)
        rect2 = checked.rectified(obs, "navcam")
        assert checked.epipolar["navcam"].correction is not None and len(events) == 1 and "navcam" in events[0]
        R_turn = rect2.rig.left.T_rover_cam[:3, :3].T @ rig.left.T_rover_cam[:3, :3]
        assert 0.0 < np.degrees(np.arccos(min(1.0, (np.trace(R_turn) - 1) / 2))) < 0.1
        assert not np.array_equal(rect2.right_u8, rect.right_u8)
    finally:
        world.close()


def test_one_gl_context_draws_every_pair_size_like_an_own_size_context(render_world, lens_renderer):
    """The flight lenses draw each pair at its own size, all in one GL context (render/gl.py set_viewport): a pair
    drawn after a larger one equals the same pair drawn by a context made for exactly its size, as each size had
    before (a viewport read from the wrong corner, or kept at the previous size, would differ or fail on shape)."""
    r, _ = lens_renderer
    sizes = {pair: v.px for pair, v in r.lens.views.items()}
    assert len(set(sizes.values())) > 1, f"the flight lenses drew one size for every pair: {sizes}"
    order = sorted(sizes, key=sizes.get, reverse=True)  # largest first, then smaller viewports
    frames = {pair: r.render_pair(pair) for pair in order}
    assert len(r.contexts) == 1
    for pair in order[1:]:
        own = StereoRenderer(render_world.sim, lens=r.lens)
        try:
            own._gl, own._gl_px = mujoco.Renderer(own.world.model, sizes[pair], sizes[pair]), sizes[pair]
            want = own.render_pair(pair)
            assert own.contexts[0].width == sizes[pair]
        finally:
            own.close()
        np.testing.assert_array_equal(frames[pair].left, want.left)
        np.testing.assert_array_equal(frames[pair].right, want.right)


def test_oversampled_true_lens_integrates_each_raw_pixel_without_shifting_it() -> None:
    """``render_oversample`` 2 (the rock survey's panoramas): the raw image reads a render twice as fine, each raw
    pixel averaging its own area (a Gaussian of a one-raw-pixel box's variance) before the remap. A linear ramp
    comes through exactly (no shift: the raw pixel reads the render where its ray lands), and fine render detail
    (a one-render-pixel checkerboard) is averaged away instead of aliased, as a photosite would."""
    from nav.camera import PinholeCamera
    from nav.lens import CahvorCamera
    from rover_sim.render.lens import TrueLens

    pins = [PinholeCamera.from_fov(f"navcam_{s}", 64, 64, 45.0) for s in ("left", "right")]
    models = {p.name: CahvorCamera.from_pinhole(p, r=(0.0, -0.01, 0.003)) for p in pins}
    point = TrueLens(models, 1.0, LensErrorSpec().hazcam_max_off_axis_deg)
    area = TrueLens(models, 2.0, LensErrorSpec().hazcam_max_off_axis_deg)
    assert point.area_sigma_px == 0.0 and area.area_sigma_px == pytest.approx(2.0 / np.sqrt(12.0))
    px = area.views["navcam"].px
    assert px >= 2 * 64
    u = np.tile(np.arange(px, dtype=np.float32), (px, 1))
    raw = area.to_raw(u, "navcam_left")
    mx = area.views["navcam"].maps["navcam_left"][0]
    inner = (slice(8, -8), slice(8, -8))
    np.testing.assert_allclose(raw[inner], mx[inner], atol=1e-3)
    checker = ((np.indices((px, px)).sum(axis=0) % 2) * 200.0).astype(np.float32)
    assert np.std(area.to_raw(checker, "navcam_left")[inner]) < 0.2 * np.std(checker)
