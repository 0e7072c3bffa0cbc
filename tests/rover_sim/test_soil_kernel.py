"""The compiled wheel–soil kernel computes exactly what its own Python body computes (no fastmath, same libm,
Python's min/max semantics), on random inputs covering contact/no contact, held and reversed wheels, sand,
bedrock, mixed and rock contacts; and the simulator's compiled path matches the law's list API."""

from __future__ import annotations

import numpy as np
import pytest

from rover_sim.sim.soil_kernel import apply_wheel_wrenches, bekker_wheels, materials_under
from rover_sim.sim.terramechanics import WheelSoilLaw

N = 6


def random_sensor_block(rng: np.random.Generator, max_load_n: float = 300.0, contact_span_m: float = 3.0) -> np.ndarray:
    """One sensor block (models/mer/rover.xml layout): some wheels off the ground, some held, some reversing
    (shared with test_wr_kernel.py)."""
    contact = np.zeros((N, 7))
    load = rng.uniform(0.0, max_load_n, N) * (rng.random(N) > 0.2)
    normal = rng.normal(size=(N, 3)) * 0.2 + [0.0, 0.0, -1.0]
    contact[:, 1:4] = normal / np.linalg.norm(normal, axis=1, keepdims=True) * load[:, None]
    contact[:, 0] = load > 0
    contact[:, 4:7] = rng.uniform(-contact_span_m, contact_span_m, (N, 3))
    vel = rng.normal(scale=0.05, size=(N, 3))
    heading = rng.normal(size=(N, 3)) + [1.0, 0.0, 0.0]
    heading /= np.linalg.norm(heading, axis=1, keepdims=True)
    rate = rng.normal(scale=0.4, size=N) * (rng.random(N) > 0.15)  # some wheels held (rate 0)
    return np.concatenate([contact.ravel(), vel.ravel(), heading.ravel(), rate])


def _run(fn, law: WheelSoilLaw, blocks: list[np.ndarray], mats: list[np.ndarray]) -> np.ndarray:
    jx, jy, patch, out = np.zeros(N), np.zeros(N), np.full(N, 0.1), np.zeros((6, N))
    trace = []
    for sd, m in zip(blocks, mats, strict=True):
        forces = np.zeros((N, 3))
        fn(sd, m, law._consts_arr, jx, jy, patch, out, forces, 0.005, law.radius_m, False, law.mass_share_kg)
        trace.append(np.concatenate([forces.ravel(), jx, jy, patch, out.ravel()]))
    return np.array(trace)


def test_compiled_law_is_bit_identical_to_its_python_body() -> None:
    rng = np.random.default_rng(7)
    law = WheelSoilLaw()
    blocks = [random_sensor_block(rng) for _ in range(300)]
    mats = [rng.integers(0, 3, N).astype(np.int64) for _ in range(300)]
    compiled = _run(bekker_wheels, law, blocks, mats)
    python = _run(bekker_wheels.py_func, law, blocks, mats)
    assert np.isfinite(compiled[:, : 3 * N]).all() and np.abs(compiled[:, : 3 * N]).max() > 1.0  # real forces
    np.testing.assert_array_equal(compiled.view(np.uint64), python.view(np.uint64))  # bits, NaNs included


def test_material_lookup_and_wrenches_match_their_python_bodies() -> None:
    rng = np.random.default_rng(3)
    heights = rng.normal(scale=0.05, size=(40, 60))
    material_grid = rng.integers(0, 3, heights.shape).astype(np.int64)
    grid = np.array([0.3, -0.2, 1.5, 1.0, 20.0])  # origin, half extents, 1 / cell
    for _ in range(50):
        sd = random_sensor_block(rng)
        sd[6:42:7] = rng.uniform(-0.1, 0.3, N)  # contact heights: some on rocks (above the margin)
        got, want = np.zeros(N, np.int64), np.zeros(N, np.int64)
        materials_under(sd, heights, material_grid, grid, 0.03, 3, got)
        materials_under.py_func(sd, heights, material_grid, grid, 0.03, 3, want)
        np.testing.assert_array_equal(got, want)
        forces, ids, xipos = rng.normal(size=(N, 3)), np.arange(2, 2 + N), rng.normal(size=(10, 3))
        a, b = np.zeros((10, 6)), np.zeros((10, 6))
        apply_wheel_wrenches(sd, forces, ids, xipos, a)
        apply_wheel_wrenches.py_func(sd, forces, ids, xipos, b)
        np.testing.assert_array_equal(a, b)
        assert (a[:2] == 0).all() and (a[ids, :3] == forces).all()  # only the wheel bodies' rows are written
    assert set(np.unique(got)) <= {0, 1, 2, 3}


@pytest.mark.parametrize("material", [0, 1, 2])
def test_list_api_equals_array_api(material: int) -> None:
    rng = np.random.default_rng(material)
    a, b = WheelSoilLaw(), WheelSoilLaw()
    for _ in range(20):
        sd = random_sensor_block(rng)
        f_list = a.evaluate(sd.tolist(), [material] * N, 0.005)
        f_arr = np.zeros((N, 3))
        b.evaluate_into(sd, np.full(N, material, dtype=np.int64), 0.005, f_arr)
        assert f_list == f_arr.ravel().tolist()
    np.testing.assert_array_equal(a.state.sinkage_m, b.state.sinkage_m)
