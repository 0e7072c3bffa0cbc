"""The onboard shadow prediction (nav.vo.shadow) against a ground-truth render.

Truth: the same navcam view rendered with and without shadows (no image noise); terrain pixels (segmentation)
that the shadow darkens are the rover's shadow (no rocks in this field). The prediction uses only onboard
knowledge: the sun's direction, the rover's shape from the MJCF, the calibrated camera model and the attitude.
"""

from __future__ import annotations

import numpy as np
import pytest

from nav.vo.shadow import predict_shadow, vo_feature_mask
from rover_sim.scenario.loading import scenario_from_dict
from rover_sim.sim.assembly import Sun
from rover_sim.world.rover_shape import rover_shape
from rover_sim.world.world import World

FIELD = {
    "name": "shadow_probe",
    "terrain": {
        "size_m": [8, 8],
        "cell_size_m": 0.05,
        "roughness": {"rms_m": 0.002, "correlation_length_m": 1.0},
        "rocks": {"cover_fraction": 0.0},
    },
    "appearance": {"fine_soil": True},
    "commands": [{"type": "drive", "distance_m": 0.1}],
    # the predictor's geometry against rendered truth: pinhole images in the same frame as the segmentation render
    # (the flight profile's raw images are not); shadow VO on the flight profile is judged by sol235_shadow
    "sensors": {"profile": "ideal"},
}
SHADOW_DARKENING_GREY = 8  # grey levels: the shadowed ground is ~50 levels darker, noise is off


@pytest.mark.parametrize(
    ("azimuth_deg", "elevation_deg", "pan_deg"),
    [(180, 25, 0), (150, 35, 0), (210, 20, 20), (180, 60, 0)],
)
def test_predicted_shadow_covers_the_true_shadow(azimuth_deg, elevation_deg, pan_deg):
    sc = scenario_from_dict(
        FIELD
        | {
            "sun": {"azimuth_deg": azimuth_deg, "elevation_deg": elevation_deg},
            "nav": {"image_noise": False, "mast_tilt_deg": -50, "mast_pan_deg": pan_deg},
        }
    )
    world = World(sc)
    try:
        r = world.renderer
        r.shadows = True
        lit = r.render_grey("navcam_left").astype(float)
        r.shadows = False
        unlit = r.render_grey("navcam_left").astype(float)
        terrain = r.render_segmentation("navcam_left") == world.sim.model.geom("terrain").id
        truth = (unlit - lit > SHADOW_DARKENING_GREY) & terrain
        rig = world.onboard_rig("navcam")
        obs = world.observation()
        # onboard inputs only: ephemeris sun, design shape, calibrated rig; the attitude as the IMU gives it
        R = world.truth_pose().R_world_rover  # settled and at rest: the IMU's attitude equals it to < 0.1 deg
        pred = predict_shadow(rover_shape(), rig.left, R, obs.sun_direction_world, rig.left.T_rover_cam)
    finally:
        world.close()
    assert np.allclose(obs.sun_direction_world, Sun(azimuth_deg, elevation_deg).direction())
    p = pred.shadow & terrain
    assert truth.sum() > 1000, "the view must hold a real shadow"
    covered = (p & truth).sum() / truth.sum()
    extra = (p & ~truth).sum() / truth.sum()
    assert covered >= 0.90, f"predicted mask covers {covered:.1%} of the true shadow"
    assert extra <= 0.20, f"predicted mask adds {extra:.1%} of the true shadow's area"
    mask = vo_feature_mask(pred)
    assert not mask[truth].any(), "no feature may be picked inside the true shadow"
