"""The MER model and the physics wrapper (menagerie test/model_test.py style, plus suspension behaviour)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import rover_sim  # noqa: F401
from rover_sim.errors import PhysicsDiverged
from rover_sim.sim.assembly import ROVER_XML, SCENE_XML
from rover_sim.sim.drive import Straight, execute
from rover_sim.sim.physics import RoverSim
from terrains import (
    ExplicitRockSpec,
    MaterialSpec,
    RockSpec,
    RoughnessSpec,
    Terrain,
    TerrainRecipe,
    synthesize,
)


def _flat(material: str = "sand", explicit=(), size=(12.0, 8.0), roughness_m=0.0, seed=0):
    return synthesize(
        TerrainRecipe(
            size_m=size,
            cell_size_m=0.05,
            roughness=RoughnessSpec(rms_m=roughness_m),
            rocks=RockSpec(cover_fraction=0.0),
            explicit_rocks=list(explicit),
            material=MaterialSpec(kind=material),
        ),
        seed,
    )


@pytest.mark.parametrize("path", [ROVER_XML, SCENE_XML])
def test_model_compiles_and_steps_with_random_controls_without_warnings(path):
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    rng = np.random.default_rng(0)
    lo, hi = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
    limited = model.actuator_ctrllimited.astype(bool)
    for _ in range(int(1.0 / model.opt.timestep)):
        ctrl = rng.uniform(-1, 1, model.nu)
        data.ctrl[:] = np.where(limited, lo + (ctrl + 1) / 2 * (hi - lo), ctrl)
        mujoco.mj_step(model, data)
    assert [w.number for w in data.warning] == [0] * len(data.warning)
    assert np.isfinite(data.qpos).all()


def test_every_element_is_named_and_home_exists():
    m = mujoco.MjModel.from_xml_path(str(SCENE_XML))
    for kind, n in [
        (mujoco.mjtObj.mjOBJ_BODY, m.nbody),
        (mujoco.mjtObj.mjOBJ_JOINT, m.njnt),
        (mujoco.mjtObj.mjOBJ_ACTUATOR, m.nu),
        (mujoco.mjtObj.mjOBJ_SENSOR, m.nsensor),
        (mujoco.mjtObj.mjOBJ_SITE, m.nsite),
        (mujoco.mjtObj.mjOBJ_CAMERA, m.ncam),
    ]:
        names = [mujoco.mj_id2name(m, kind, i) for i in range(n)]
        assert all(names), f"unnamed {kind}: {names}"
    assert m.key("home").id == 0
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert 170 <= m.body_subtreemass[m.body("rover").id] <= 178  # MER: about 174 kg


def test_mer_dimensions():
    m = mujoco.MjModel.from_xml_path(str(SCENE_XML))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_forward(m, d)
    wheel = {w: d.xpos[m.body(f"wheel_{w}").id] for w in ("lf", "lm", "lr", "rf", "rm", "rr")}
    assert wheel["lf"][0] - wheel["lr"][0] == pytest.approx(1.1, abs=0.05)  # wheelbase
    assert wheel["lm"][1] - wheel["rm"][1] == pytest.approx(1.1, abs=0.1)  # track
    assert m.geom("wheel_lf").size[0] == pytest.approx(0.125)
    # navcams about 1.5 m above ground (ground at z=0 at the home pose), 20 cm baseline
    nl, nr = d.cam_xpos[m.camera("navcam_left").id], d.cam_xpos[m.camera("navcam_right").id]
    assert nl[2] == pytest.approx(1.5, abs=0.05)
    assert np.linalg.norm(nl - nr) == pytest.approx(0.20, abs=1e-6)
    hl, hr = d.cam_xpos[m.camera("hazcam_front_left").id], d.cam_xpos[m.camera("hazcam_front_right").id]
    assert hl[2] == pytest.approx(0.5, abs=0.05)
    assert np.linalg.norm(hl - hr) == pytest.approx(0.10, abs=1e-6)


def test_differential_holds_on_twisted_terrain():
    """A saddle under the wheels twists the rockers; the differential keeps them equal and opposite."""
    t = _flat(size=(8.0, 8.0))
    x, y = np.meshgrid(t.xs_m, t.ys_m)
    heights = 0.12 * x * y  # saddle: front-left and rear-right high
    sim = RoverSim(Terrain.from_heights(heights, t.cell_size_m))
    sim.place(0.0, 0.0, 0.0, settle_s=3.0)
    left, right = np.degrees(sim.rocker_angles_rad())
    assert abs(left) > 1.0, "the saddle should twist the rockers"
    assert left == pytest.approx(-right, abs=0.5)
    assert sim.wheels_in_contact().all()


def test_climbs_a_20cm_rock_keeping_six_wheels_down():
    rock = ExplicitRockSpec(
        name="step20",
        x_m=0.0,
        y_m=0.55,
        shape="semi_ellipsoid",
        length_m=0.7,
        width_m=0.7,
        buried_m=0.15,
        height_m=0.20,
    )  # partly buried: a sloping face, as most rocks
    sim = RoverSim(_flat(material="bedrock", explicit=[rock]))
    sim.place(-1.6, 0.0, 0.0)
    contact_ticks, wheel_z, on_rock = [], [], []

    def on_tick(s):
        contact_ticks.append(s.wheels_in_contact().all())
        wheel_z.append(s.wheel_centres_m()[:, 2])
        on_rock.append(s.rock_contacts(min_height_m=0.15))

    execute(sim, Straight(3.2), speed_m_s=0.05, on_tick=on_tick)
    assert sim.position_m()[0] > 1.3, "the rover got over the rock"
    lift = np.max(wheel_z, axis=0) - wheel_z[0]
    assert (lift[:3] > 0.15).all(), f"every left wheel climbed the 20 cm rock: lift {lift[:3]}"
    assert (lift[3:] < 0.05).all()
    assert np.mean(contact_ticks) == 1.0, (
        f"wheel left the ground in {100 * (1 - np.mean(contact_ticks)):.1f} % of ticks"
    )
    assert not sim.body_contacts()
    touched = {pair for hits in on_rock for pair in hits}
    assert touched and {rock for _, rock in touched} == {"step20"}
    assert {geom.split("_")[0] for geom, _ in touched} == {"wheel"}  # the left wheels rolled over it
    assert not any(on_rock[:5]) and sim.rock_contacts(min_height_m=0.25) == []


def test_body_touching_the_ground_is_a_body_contact():
    sim = RoverSim(_flat())
    sim.place(0.0, 0.0, 0.0, settle_s=0.2)
    assert sim.body_contacts() == []
    sim.data.qpos[2] -= 0.45  # sink the chassis into the ground
    mujoco.mj_forward(sim.model, sim.data)
    hits = sim.body_contacts()
    assert hits and not any(h.startswith("wheel_") for h in hits)


def test_physics_divergence_is_a_clean_error():
    sim = RoverSim(_flat(size=(6.0, 6.0)))
    sim.place(0.0, 0.0, 0.0, settle_s=0.2)
    sim.data.qvel[0] = np.nan
    with pytest.raises(PhysicsDiverged, match=r"t=\d+\.\d+ s"):
        sim.step(None, 5)
