"""MER stereo on rendered hazcam pairs with ground truth (the `rover-sim bench stereo` acceptance), and the
`rover-sim stereo` command.

The rendered pairs (sand and bedrock, one seed each, 256x256 front hazcams) are made once for the module; each must
get a disparity on >= 90 % of the scored pixels (terrain and rocks within 3 m), >= 95 % of them within 1 px of the
rendered depth's disparity. Seed 3 is not one of the benchmark's seeds (0, 1, 2).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import typer
from typer.testing import CliRunner

import rover_sim  # noqa: F401  (first: sets MUJOCO_GL=egl before anything imports mujoco)
from nav.stereo import StereoParams, compute_disparity, stereobm_baseline
from rover_sim.bench.stereo import NUM_DISPARITIES, SimPair, score, simulated_pairs
from rover_sim.cli.stereo import StereoInputError, disparity_from_files, load_grey, stereo_cmd

SEEDS = (3,)


@pytest.fixture(scope="module")
def sim_pairs() -> list[SimPair]:
    return simulated_pairs(seeds=SEEDS, materials=("sand", "bedrock"))


@pytest.fixture(scope="module")
def sim_results(sim_pairs: list[SimPair]) -> list[tuple[str, tuple[float, float], tuple[float, float]]]:
    params = StereoParams(num_disparities=NUM_DISPARITIES)
    return [
        (
            p.label,
            score(compute_disparity(p.left, p.right, params), p.gt_disparity_px),
            score(stereobm_baseline(p.left, p.right, NUM_DISPARITIES, params.window_px), p.gt_disparity_px),
        )
        for p in sim_pairs
    ]


@pytest.mark.render
def test_each_rendered_pair_is_dense_and_accurate(sim_results) -> None:
    assert {label.split("/")[0] for label, _, _ in sim_results} == {"sand", "bedrock"}
    for label, (density, bad1), _ in sim_results:
        assert density >= 0.90, f"{label}: density {density:.3f}"
        assert 1.0 - bad1 >= 0.95, f"{label}: within 1 px {1 - bad1:.4f}"


@pytest.mark.render
def test_fewer_bad_pixels_than_stereobm(sim_results) -> None:
    ours = np.mean([r[1][1] for r in sim_results])
    bm = np.mean([r[2][1] for r in sim_results])
    assert ours < bm, f"bad-1px ours {ours:.4f} vs StereoBM {bm:.4f}"


@pytest.mark.render
def test_ground_truth_is_scored_near_the_rover(sim_pairs: list[SimPair]) -> None:
    """The scored pixels are a real test: thousands of them, disparities over most of the searched range."""
    for p in sim_pairs:
        gt = p.gt_disparity_px[np.isfinite(p.gt_disparity_px)]
        assert gt.size > 20_000
        assert gt.min() < 5.0 and gt.max() > 20.0


# ----------------------------------------------------------------------------------------------------------------
# rover-sim stereo
# ----------------------------------------------------------------------------------------------------------------


def textured_pair(disparity_px: float = 12.0, shape: tuple[int, int] = (96, 128)) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    h_px, w_px = shape
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (h_px, w_px + 32)).astype(np.float32), (0, 0), 1.2)
    tex = cv2.normalize(tex, None, 20, 235, cv2.NORM_MINMAX)
    xs, ys = np.meshgrid(np.arange(w_px, dtype=np.float32), np.arange(h_px, dtype=np.float32))
    right = cv2.remap(tex, xs + np.float32(disparity_px), ys, cv2.INTER_CUBIC)
    return np.rint(tex[:, :w_px]).astype(np.uint8), np.clip(np.rint(right), 0, 255).astype(np.uint8)


@pytest.fixture()
def png_pair(tmp_path: Path) -> tuple[Path, Path]:
    left, right = textured_pair()
    paths = tmp_path / "left.png", tmp_path / "right.png"
    cv2.imwrite(str(paths[0]), left)
    cv2.imwrite(str(paths[1]), cv2.cvtColor(right, cv2.COLOR_GRAY2BGR))  # grey stored as BGR is still grey
    return paths


def cli_app() -> typer.Typer:
    app = typer.Typer()
    app.command("stereo")(stereo_cmd)
    app.command("other")(lambda: None)  # more than one command: `stereo` is a subcommand, as in rover-sim
    return app


def test_stereo_command_writes_the_disparity(png_pair: tuple[Path, Path], tmp_path: Path) -> None:
    out = tmp_path / "sub" / "disp.npy"
    args = ["stereo", str(png_pair[0]), str(png_pair[1]), "--num-disparities", "32", "--out", str(out)]
    res = CliRunner().invoke(cli_app(), args)
    assert res.exit_code == 0, res.output
    d = np.load(out)
    assert d.dtype == np.float32 and d.shape == (96, 128)
    assert np.isfinite(d).mean() > 0.5
    assert np.nanmedian(d) == pytest.approx(12.0, abs=0.15)
    left, right = textured_pair()
    np.testing.assert_array_equal(d, compute_disparity(left, right, StereoParams(num_disparities=32)))


def test_stereo_command_errors_name_the_file(png_pair: tuple[Path, Path], tmp_path: Path) -> None:
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((50, 60), np.uint8))
    runner, out = CliRunner(), str(tmp_path / "d.npy")
    res = runner.invoke(cli_app(), ["stereo", str(png_pair[0]), str(small), "--out", out])
    assert res.exit_code == 2
    assert "small.png" in res.output and "60x50" in res.output and "128x96" in res.output
    missing = tmp_path / "nope.png"
    res = runner.invoke(cli_app(), ["stereo", str(missing), str(png_pair[1]), "--out", out])
    assert res.exit_code == 2 and "nope.png" in res.output
    res = runner.invoke(cli_app(), ["stereo", *map(str, png_pair), "--num-disparities", "40", "--out", out])
    assert res.exit_code == 2 and "num_disparities" in res.output
    assert not Path(out).exists()


def test_colour_input_is_an_error_naming_the_file(png_pair: tuple[Path, Path], tmp_path: Path) -> None:
    left, _ = textured_pair()
    colour = cv2.merge([left, np.roll(left, 3, axis=1), 255 - left])  # channels differ: a colour image
    cv2.imwrite(str(tmp_path / "colour.png"), colour)
    out = tmp_path / "d.npy"
    res = CliRunner().invoke(cli_app(), ["stereo", str(tmp_path / "colour.png"), str(png_pair[1]), "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert "colour.png" in res.output and "greyscale rectified image" in res.output
    assert not out.exists()


def test_load_grey_conversions_and_rejections(tmp_path: Path) -> None:
    grey16 = np.full((8, 10), 65535, np.uint16)
    cv2.imwrite(str(tmp_path / "g16.png"), grey16)
    assert load_grey(tmp_path / "g16.png").dtype == np.uint8 and load_grey(tmp_path / "g16.png").max() == 255
    bgra = np.zeros((8, 10, 4), np.uint8)
    cv2.imwrite(str(tmp_path / "c4.png"), bgra)
    assert load_grey(tmp_path / "c4.png").shape == (8, 10)
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(StereoInputError, match="text.png"):
        load_grey(tmp_path / "text.png")
    big = tmp_path / "big.png"
    cv2.imwrite(str(big), np.zeros((8, 5000), np.uint8))  # beyond 4096 px a side (1024^2 is fine)
    with pytest.raises(StereoInputError, match="big.png.*bin it"):
        disparity_from_files(big, big)


def test_bench_stereo_refuses_an_unknown_profile() -> None:
    from rover_sim.bench.stereo import num_disparities, pairs_for_profile
    from rover_sim.errors import ConfigError

    with pytest.raises(ConfigError, match="ideal, flight"):
        pairs_for_profile("pinhole", 256)
    assert (num_disparities(256), num_disparities(1024)) == (NUM_DISPARITIES, 4 * NUM_DISPARITIES)  # same metres


def test_a_matcher_that_returns_nothing_does_not_beat_stereobm() -> None:
    from rover_sim.runtime.acceptance.bars import stereo_verdict

    bm = {"stereobm_bad1": 0.0031, "stereobm_density": 0.87, "ratio": 1.2, "ratio_1024": 1.4, "engines_agree": True}
    assert stereo_verdict(bm | {"ours_bad1": 0.0014, "ours_density": 0.927}).passed
    nothing = stereo_verdict(bm | {"ours_bad1": 0.0, "ours_density": 0.0})  # no disparity at all
    assert not nothing.passed and nothing.reasons == ["density 0.0 % < StereoBM 87.0 %"]
    assert not stereo_verdict(bm | {"ours_bad1": 0.0040, "ours_density": 0.95}).passed
    slow = stereo_verdict(bm | {"ours_bad1": 0.0014, "ours_density": 0.927, "ratio_1024": 1.6})
    assert slow.reasons == ["speed ratio to StereoBM @1024 px 1.60 > 1.5"]


@pytest.mark.render
def test_flight_pairs_are_rectified_raw_images_with_true_ground_truth() -> None:
    """Flight pair (raw through the true lenses, CCD formation, rectified with the erroneous onboard calibration):
    its ground truth follows the true correspondence, so our SAD stays within 1 px of it almost everywhere, while
    the same images scored against the onboard rig's own depth->disparity would not be exact."""
    from rover_sim.bench.stereo import params_for, score, simulated_pairs

    (p,) = simulated_pairs(seeds=(0,), materials=("sand",), profile="flight")
    assert p.left.shape == (256, 256) and np.isfinite(p.gt_disparity_px).mean() > 0.2
    density, bad1 = score(compute_disparity(p.left, p.right, params_for(256)), p.gt_disparity_px)
    assert density > 0.6 and bad1 < 0.05, (density, bad1)


@pytest.mark.render
def test_rendered_1024_pair_matches_its_depth() -> None:
    """Full-resolution (1024^2) hazcam pair: dense and within 1 px of the rendered depth's disparity."""
    from rover_sim.bench.stereo import params_for

    (pair,) = simulated_pairs(seeds=(3,), materials=("sand",), resolution_px=1024)
    params = params_for(1024)
    assert params == StereoParams(num_disparities=128, bandpass_sigma_fine_px=1.2, bandpass_sigma_coarse_px=5.0)
    density, bad1 = score(compute_disparity(pair.left, pair.right, params), pair.gt_disparity_px)
    bm_density, bm_bad1 = score(stereobm_baseline(pair.left, pair.right, 128, 9), pair.gt_disparity_px)
    assert density >= 0.75 and bad1 <= 0.015, (density, bad1)
    assert bad1 < bm_bad1, (bad1, bm_bad1)
