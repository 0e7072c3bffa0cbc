"""`rover-sim stereo LEFT.png RIGHT.png --num-disparities N --out DISP.npy`: MER stereo on a rectified image pair.

:func:`stereo_cmd` is the command (typer reads its annotations); :func:`load_pair` and :func:`disparity_from_files`
are the library functions behind it. The images must be rectified (rows are epipolar lines), the same size, and
greyscale (8- or 16-bit; a 3- or 4-channel file whose colour channels are all equal is grey too). A colour image is
refused: which grey a colour camera's channels should make depends on the camera, and matching the wrong one
silently degrades the disparity. The output is the left-referenced disparity in pixels as a float32 ``.npy`` array,
NaN where no disparity passed the checks (see :mod:`nav.stereo`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import cv2
import numpy as np
import typer

from nav.stereo import StereoParams, compute_disparity
from rover_sim.errors import RoverSimError


class StereoInputError(RoverSimError):
    """An input image of `rover-sim stereo` cannot be used; the message names the file and the fix."""


def load_grey(path: Path) -> np.ndarray:
    """An image file as 8-bit greyscale (16-bit grey is scaled by 255/65535); colour is refused."""
    path = Path(path)
    if not path.is_file():
        raise StereoInputError(f"{path}: no such file")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise StereoInputError(f"{path}: not an image OpenCV can read (use PNG)")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3 and img.shape[2] in (3, 4):
        colour = img[:, :, :3]
        if not (np.array_equal(colour[:, :, 0], colour[:, :, 1]) and np.array_equal(colour[:, :, 0], colour[:, :, 2])):
            raise StereoInputError(
                f"{path}: a colour image; stereo needs a greyscale rectified image (convert it with the weighting "
                "your camera needs, e.g. cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), and rectify it first)"
            )
        img = colour[:, :, 0]
    if img.ndim != 2:
        raise StereoInputError(f"{path}: {img.shape[2]} channels; need a greyscale rectified image (1 channel)")
    if img.dtype == np.uint16:
        img = cv2.convertScaleAbs(img, alpha=255.0 / 65535.0)
    if img.dtype != np.uint8:
        raise StereoInputError(f"{path}: {img.dtype} pixels; need 8- or 16-bit integers")
    return img


def load_pair(left: Path, right: Path) -> tuple[np.ndarray, np.ndarray]:
    """Both images as 8-bit greyscale; they must be the same size."""
    left_img, right_img = load_grey(left), load_grey(right)
    if left_img.shape != right_img.shape:
        raise StereoInputError(
            f"{left} is {left_img.shape[1]}x{left_img.shape[0]} px but {right} is "
            f"{right_img.shape[1]}x{right_img.shape[0]} px: a rectified pair has one size"
        )
    return left_img, right_img


def disparity_from_files(left: Path, right: Path, num_disparities: int = 64, window_px: int = 9) -> np.ndarray:
    """Left-referenced disparity (px, float32, NaN where invalid) of a rectified pair of image files."""
    left_img, right_img = load_pair(left, right)
    try:
        params = StereoParams(num_disparities=num_disparities, window_px=window_px)
    except ValueError as e:
        raise StereoInputError(str(e)) from None
    try:
        return compute_disparity(left_img, right_img, params)
    except ValueError as e:  # too large for one call
        raise StereoInputError(f"{left}, {right}: {e}") from None


def stereo_cmd(
    left: Annotated[Path, typer.Argument(help="Left rectified image (PNG, greyscale; colour is refused).")],
    right: Annotated[Path, typer.Argument(help="Right rectified image, the same size.")],
    num_disparities: Annotated[
        int, typer.Option("--num-disparities", help="Disparities searched: a multiple of 16, at most 256.")
    ] = 64,
    out: Annotated[Path, typer.Option("--out", help="Output disparity, float32 .npy (NaN = none).")] = Path(
        "disparity.npy"
    ),
    window_px: Annotated[int, typer.Option("--window", help="SAD window side, odd, 3..21 px.")] = 9,
) -> None:
    """MER SAD stereo (band-pass, SAD, checks, quadratic sub-pixel) on a rectified pair; writes the disparity."""
    try:
        disparity = disparity_from_files(left, right, num_disparities, window_px)
    except RoverSimError as e:
        typer.secho(f"error: {e}", fg=typer.colors.RED, err=True)
        raise typer.Exit(code=2) from None
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.save(out, disparity.astype(np.float32, copy=False))
    valid = np.isfinite(disparity)
    span = f", {np.min(disparity[valid]):.1f}..{np.max(disparity[valid]):.1f} px" if valid.any() else ""
    typer.echo(f"{out}: {disparity.shape[1]}x{disparity.shape[0]}, {100 * valid.mean():.1f} % valid{span}")
