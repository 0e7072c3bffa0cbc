"""The compiled Wong–Reece kernels (rover_sim/sim/wr_kernel.py) compute exactly what their own Python bodies compute
(no fastmath, same libm, Python's min/max and hypot), bit for bit, on random inputs covering contact and lift-off,
held, reversed and dragged wheels, every material, ruts, berms and bedrock cells; and a whole deformable drive run
with the compiled kernels equals the same drive run through their Python bodies."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rover_sim.sim import deform, physics, terramechanics_wr
from rover_sim.sim.terramechanics_wr import WheelSoilLaw
from rover_sim.sim.wr_kernel import (
    deform_after_law,
    py_hypot,
    table_lookup,
    wr_wheels,
    wr_wrenches,
)
from terrains import MaterialSpec, RockSpec, RoughnessSpec, SlopeSpec, TerrainRecipe, synthesize
from tests.rover_sim.test_soil_kernel import random_sensor_block

N = 6


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float).view(np.uint64)


def _random_block(rng: np.random.Generator) -> np.ndarray:
    return random_sensor_block(rng, max_load_n=400.0, contact_span_m=1.5)


def test_py_hypot_is_cpythons_math_hypot() -> None:
    rng = np.random.default_rng(1)
    xs = np.concatenate([rng.normal(size=20000), rng.normal(size=2000) * 1e-310, rng.normal(size=2000) * 1e300])
    ys = xs[::-1] * rng.choice([1.0, 1e-6, 0.0], xs.size)
    special = [0.0, -0.0, math.inf, -math.inf, math.nan, 5e-324, 1.0]
    pairs = list(zip(xs.tolist(), ys.tolist(), strict=True)) + [(a, b) for a in special for b in special]
    got = np.array([py_hypot(a, b) for a, b in pairs])
    want = np.array([math.hypot(a, b) for a, b in pairs])
    np.testing.assert_array_equal(_bits(got), _bits(want))


def test_table_lookup_is_bit_identical_to_its_python_body() -> None:
    law = WheelSoilLaw()
    rng = np.random.default_rng(2)
    for material in range(len(law.materials)):
        rows, inv_du = law._tables[material], float(law._consts[material, 0])
        for load, slip in zip(rng.uniform(-10.0, 700.0, 300), rng.uniform(-1.3, 1.3, 300), strict=True):
            got = table_lookup(rows, inv_du, float(load), float(slip))
            want = table_lookup.py_func(rows, inv_du, float(load), float(slip))
            np.testing.assert_array_equal(_bits(np.array(got)), _bits(np.array(want)))
    assert law.lookup(0, 108.0, 0.6)[0] > law.lookup(0, 108.0, 0.0)[0] > 0.0  # a real table: slip-sinkage


def _run_law(fn, blocks: list[np.ndarray], mats: list[np.ndarray]) -> np.ndarray:
    law = WheelSoilLaw()
    trace = []
    for k, (sd, m) in enumerate(zip(blocks, mats, strict=True)):
        law.presink_m[:] = 0.01 * (k % 3)  # ruts of earlier passes ahead of the wheels (multipass)
        forces = np.zeros((N, 4))
        fn(sd, m, law._tables, law._consts, law.state_arrays(), law._vf, law.out_state(), law.axles, forces,
           0.005, law.radius_m, law.mass_share_kg)  # fmt: skip
        trace.append(np.concatenate([forces.ravel(), law.state_arrays().ravel(), law.out_state().ravel(),
                                     law.axles.ravel()]))  # fmt: skip
    return np.array(trace)


def test_law_is_bit_identical_to_its_python_body() -> None:
    rng = np.random.default_rng(7)
    blocks, mats = [], []
    for k in range(400):
        sd = _random_block(rng)
        if k % 50 > 40:  # stretches of one wheel in the air (lift-off keeps and renews the shear state)
            sd[7 : 7 + 4] = 0.0
        blocks.append(sd)
        mats.append(rng.integers(0, 4, N).astype(np.int64))
    compiled = _run_law(wr_wheels, blocks, mats)
    python = _run_law(wr_wheels.py_func, blocks, mats)
    forces = compiled[:, : 4 * N]
    assert np.isfinite(forces).all() and np.abs(forces).max() > 10.0  # real forces
    assert (forces == 0.0).all(axis=1).sum() < 10  # not everything in the air
    np.testing.assert_array_equal(compiled.view(np.uint64), python.view(np.uint64))  # bits, NaNs included


def test_wrenches_are_bit_identical_to_their_python_body() -> None:
    rng = np.random.default_rng(4)
    for _ in range(50):
        sd, forces = _random_block(rng), rng.normal(scale=50.0, size=(N, 4))
        axles = rng.normal(size=(N, 3))
        axles /= np.linalg.norm(axles, axis=1, keepdims=True)
        ids, xipos = np.arange(2, 2 + N), rng.normal(size=(10, 3))
        a, b = np.zeros((10, 6)), np.zeros((10, 6))
        wr_wrenches(sd, forces, axles, ids, xipos, a)
        wr_wrenches.py_func(sd, forces, axles, ids, xipos, b)
        np.testing.assert_array_equal(_bits(a), _bits(b))
        assert (a[:2] == 0).all() and (a[ids, :3] == forces[:, :3]).all()
        # the torque about each axle is the law's soil torque (minus T), whatever the lever of the force
        np.testing.assert_allclose(np.einsum("ij,ij->i", a[ids, 3:], axles), -forces[:, 3], atol=1e-9)


def _run_deform(fn, rng: np.random.Generator, steps: int = 300):
    nrow, ncol, cell = 60, 80, 0.04
    h0 = rng.normal(scale=0.01, size=(nrow, ncol))
    soft = rng.random((nrow, ncol)) > 0.1  # some bedrock cells in the sand
    h, hfield = h0.copy(), np.zeros(nrow * ncol + 7, dtype=np.float32)
    p = np.array([cell, -1.6, -1.2, -0.3, 0.6, 0.005 / 0.505, 0.16, 0.125])
    out, state, axles = np.zeros((7, N)), np.zeros((5, N)), np.zeros((N, 3))
    state[3] = 0.1
    zf, last, dirty = np.zeros(N), np.tile([np.inf, np.inf, 0.0], (N, 1)), np.zeros((2, 5), dtype=np.int64)
    xpos, ids = np.zeros((8, 3)), np.arange(1, 1 + N)
    xpos[ids, 0] = np.linspace(-1.0, 0.0, N)
    xpos[ids, 1] = np.linspace(-0.5, 0.5, N)
    soft_material, trace = np.array([True, False, True, True]), []
    for k in range(steps):
        xpos[ids, 0] += 0.03 * math.cos(0.05 * k) + rng.uniform(0.0, 0.004, N)  # to and fro, a write most steps
        xpos[ids, 1] += rng.normal(scale=0.001, size=N)
        sd = _random_block(rng)
        sd[4:42:7] = xpos[ids, 0] + rng.normal(scale=0.02, size=N)
        sd[5:42:7] = xpos[ids, 1] + rng.normal(scale=0.02, size=N)
        out[0] = rng.uniform(20.0, 200.0, N) * (k % 60 < 55)  # now and then in the air (the low-pass restarts)
        out[1] = rng.uniform(0.0, 0.05, N)
        state[3] = rng.uniform(0.05, 0.15, N)
        axles[:] = rng.normal(scale=0.1, size=(N, 3)) + [0.0, 1.0, 0.0]
        mats = rng.choice(np.array([0, 0, 0, 0, 1, 2, 3]), N)  # mostly sand, now and then on rock
        fn(sd, mats, soft_material, out, state, axles, xpos, ids, h, h0, soft, hfield, 3, p, zf, last, dirty)
        trace.append(np.concatenate([state.ravel(), zf, last.ravel(), dirty.ravel().astype(float)]))
    return np.array(trace), h, h0, soft, hfield


def test_deformable_terrain_is_bit_identical_to_its_python_body() -> None:
    t_c, h, h0, soft, hf_c = _run_deform(deform_after_law, np.random.default_rng(5))
    t_p, h_p, _, _, hf_p = _run_deform(deform_after_law.py_func, np.random.default_rng(5))
    np.testing.assert_array_equal(t_c.view(np.uint64), t_p.view(np.uint64))
    np.testing.assert_array_equal(_bits(h), _bits(h_p))
    np.testing.assert_array_equal(hf_c.view(np.uint32), hf_p.view(np.uint32))
    assert (h < h0 - 0.003).sum() > 50 and (h > h0 + 1e-4).sum() > 50  # ruts and berms were written
    assert (h[~soft] == h0[~soft]).all()  # bedrock never changes
    np.testing.assert_array_equal(hf_c[3:-4].reshape(h.shape)[h != h0], ((h - -0.3) / 0.6).astype(np.float32)[h != h0])


def _drive(steps: int) -> tuple[np.ndarray, np.ndarray]:
    recipe = TerrainRecipe(size_m=(6.0, 5.0), cell_size_m=0.04, slope=SlopeSpec(slope_deg=5.0, azimuth_deg=20.0),
                           roughness=RoughnessSpec(rms_m=0.02, correlation_length_m=0.5),
                           rocks=RockSpec(cover_fraction=0.1),
                           material=MaterialSpec(kind="patches", bedrock_fraction=0.3, patch_scale_m=0.4))  # fmt: skip
    sim = physics.RoverSim(synthesize(recipe, 3), soil_model="wong_reece")
    sim.enable_deformation()
    sim.place(-1.0, 0.0, 0.0, settle_s=0.1)
    qpos = []
    for k in range(steps):
        sim.set_steering_rad(np.full(4, 0.25 if k > steps // 2 else 0.0) * [1, 1, -1, -1])
        sim.step(np.full(6, 0.8), 1)
        qpos.append(sim.data.qpos.copy())
    return np.array(qpos), sim.terrain_heights_m()


def test_deformable_drive_compiled_equals_python(monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole loop (law, wrenches, ruts) through the compiled kernels and through their Python bodies."""
    q_c, h_c = _drive(400)
    monkeypatch.setattr(terramechanics_wr, "wr_wheels", wr_wheels.py_func)
    monkeypatch.setattr(physics, "wr_wrenches", wr_wrenches.py_func)
    monkeypatch.setattr(deform, "deform_after_law", deform_after_law.py_func)
    q_p, h_p = _drive(400)
    np.testing.assert_array_equal(q_c.view(np.uint64), q_p.view(np.uint64))
    np.testing.assert_array_equal(h_c.view(np.uint64), h_p.view(np.uint64))
    assert np.linalg.norm(q_c[-1, :2] - q_c[0, :2]) > 0.05  # the rover drove
