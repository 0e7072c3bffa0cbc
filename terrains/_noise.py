"""Shared random-field helpers (FFT filtering of white noise), used by synthesis and appearance.

Fields are periodic (the FFT wraps around); for terrain patches and textures that is harmless and keeps every
filter a single multiply in the frequency domain.
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft


def layer_rng(seed: int, layer: int) -> np.random.Generator:
    """An independent generator for one named layer of one seed.

    ``SeedSequence(seed, spawn_key=(layer,))`` gives a stream that depends only on ``(seed, layer)``: adding,
    removing or re-ordering other layers never changes this one.
    """
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(layer),)))


def wavenumber_sq_per_px2(shape: tuple[int, int]) -> np.ndarray:
    """``kx^2 + ky^2`` (cycles per pixel, squared) on the ``rfft2`` grid, shape ``(nrow, ncol // 2 + 1)``."""
    ky = sfft.fftfreq(shape[0])[:, None]
    kx = sfft.rfftfreq(shape[1])[None, :]
    return ky * ky + kx * kx


def filtered_noise(shape: tuple[int, int], transfer: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """White Gaussian noise filtered by ``transfer`` (on the ``rfft2`` grid), zero mean, unit std."""
    white = rng.standard_normal(shape, dtype=np.float64)
    field = sfft.irfft2(sfft.rfft2(white, workers=-1) * transfer, s=shape, workers=-1)
    return _standardise(field)


def max_sigma_px(shape: tuple[int, int]) -> float:
    """Longest smoothing scale a periodic field of this shape can show: a quarter of its longer side.

    A Gaussian much wider than the grid would leave only the mean, and standardising that would amplify
    rounding noise; scales are clamped here instead (the patch then sees one smooth undulation).
    """
    return 0.25 * max(shape)


def gaussian_transfer(shape: tuple[int, int], sigma_px: float) -> np.ndarray:
    """Frequency response of a Gaussian blur of ``sigma_px`` (clamped to :func:`max_sigma_px`)."""
    sigma_px = min(sigma_px, max_sigma_px(shape))
    return np.exp(-2.0 * np.pi**2 * sigma_px**2 * wavenumber_sq_per_px2(shape))


def smooth_noise(shape: tuple[int, int], sigma_px: float, rng: np.random.Generator) -> np.ndarray:
    """White noise smoothed by a Gaussian of ``sigma_px`` pixels, zero mean and unit std.

    ``sigma_px <= 0`` returns the white noise itself (standardised).
    """
    if sigma_px <= 0.0:
        return _standardise(rng.standard_normal(shape, dtype=np.float64))
    return filtered_noise(shape, gaussian_transfer(shape, sigma_px), rng)


def _standardise(field: np.ndarray) -> np.ndarray:
    field = field - field.mean()
    std = float(field.std())
    return field / std if std > 0.0 else field
