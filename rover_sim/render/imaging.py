"""Image formation of a MER-like CCD camera: exposure control, photons, noise, 12-bit ADC, 12->8-bit companding.

Stage order (the renderer calls :meth:`ImageFormation.form` once per image, after the lens):

1. **Radiance.** The renderer's float luminance ``Y`` (0-255 scale) is taken as scene radiance times a nominal
   exposure: ``r = Y / 255``.
2. **Optics and window** (per camera, seeded): low-frequency vignetting (radial falloff, off-centre) and a few soft
   dust "donuts" (out-of-focus dust on the camera window: a dark ring with a lighter centre), and a per-camera
   gain/exposure mismatch factor. These make the two images of a pair differ photometrically.
3. **Exposure control** (MER-like auto-exposure, Maki et al. 2003, "Mars Exploration Rover engineering cameras",
   JGR 108(E12) 8071: the flight software picks the exposure time so that a high percentile of the image histogram
   lands at a target DN). Deterministic: the exposure of a pair is set from the *left* camera's current view as its
   pilot image (a converged auto-exposure on a static scene); both cameras get the same commanded exposure. No
   randomness.
4. **Photo-electrons** ``s = r * flat * t * full_well``; photon shot noise (Gaussian approximation of Poisson,
   variance ``s``), read noise, fixed pattern: PRNU (multiplicative, per photosite) and DSNU (additive offset per
   photosite), seeded per camera name, fixed over the run.
5. **12-bit ADC**: ``DN = clip(round(e / gain), 0, 4095)``.
6. **Binning 1024 -> 256** after digitisation (the order chosen here: MER's navigation images were 1024x1024 CCD
   frames reduced on board to 256x256 by averaging 4x4 blocks of 12-bit values). When the renderer rasterises
   directly at the output size (``binning=1``), each rendered pixel stands for ``(sensor_px / native_px)^2``
   photosites: the noise and fixed-pattern terms are then drawn with the variance of their block mean (a
   Gaussian approximation, exact in expectation and variance) and no per-photosite rounding is applied.
7. **12 -> 8-bit companding**: a square-root lookup table, ``DN8 = round(255 * sqrt(DN12 / 4095))`` (MER converted
   12-bit images to 8 bits with square-root-like LUTs, Maki et al. 2003 §(image processing); shot noise is then
   about uniform in 8-bit units: a "square-rooter" encodes read and shot noise equally, J. Janesick, CCD-world
   list, 1998).

Defaults of the ``flight`` profile and where they come from (approximate where marked; docs/physics/error-budget.md
quotes this table). The Maki et al. (2003) detector figures (full well, read noise) are quoted from memory of the
paper's camera table and were not re-checked against the text in this change: verify before quoting them as
published values.

=========================  ===========  =========================================================================
term                       default      source
=========================  ===========  =========================================================================
full well                  150 000 e-   Maki et al. 2003 (MER CCD, ">150 000 e-"; Pancam's identical CCD ~170k)
ADC gain                   ~37 e-/DN    full well / 4095 (the 12-bit range spans the full well)
read noise                 25 e- rms    Maki et al. 2003 (< 25 e- at Mars operating temperature)
PRNU                       1 % rms      typical frame-transfer CCD flat-field residual (approximate)
DSNU                       10 e- rms    dark-signal non-uniformity at short navcam exposures (approximate)
auto-exposure              99th pct ->  target 3500 DN of 4095 (histogram-percentile target, Maki et al. 2003;
                           3500 DN      percentile and target approximate)
vignetting                 8 % corner   low-frequency falloff left after flat-fielding (approximate)
dust donuts                3, 6 % deep  a few out-of-focus dust spots per window (approximate; MER/MSL navcams)
gain/exposure mismatch     2 % rms      per camera of a pair (approximate)
companding                 sqrt LUT     Maki et al. 2003
=========================  ===========  =========================================================================

The ``ideal`` profile (``model = "ideal"``) keeps today's images byte for byte: the renderer then uses
``quantise`` with ``ImageNoise`` (when ``nav.image_noise``) instead of this module.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

DN12_MAX = 4095
SENSOR_PX = 1024  # MER engineering-camera CCD side (Maki et al. 2003)
_SEED_TAG = 0x1A6E  # keeps the imaging streams apart from other users of the scenario seed


class ImagingSpec(BaseModel):
    """``[sensors.imaging]``: image formation of the cameras (see :mod:`rover_sim.render.imaging`)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    model: Literal["ideal", "ccd"] = Field("ideal", description="'ideal' (today's 8-bit quantisation) or 'ccd'.")
    full_well_e: float = Field(150000.0, gt=1000.0, le=1.0e6)
    read_noise_e: float = Field(25.0, ge=0.0, le=1000.0)
    prnu_rel: float = Field(0.01, ge=0.0, le=0.2, description="Photo-response non-uniformity, rms relative.")
    dsnu_e: float = Field(10.0, ge=0.0, le=1000.0, description="Dark-signal non-uniformity, rms electrons.")
    exposure_percentile: float = Field(99.0, gt=50.0, le=100.0)
    exposure_target_dn: float = Field(3500.0, gt=100.0, le=4095.0)
    vignetting_corner_rel: float = Field(0.08, ge=0.0, le=0.5, description="Brightness loss at the corners.")
    dust_spots: int = Field(3, ge=0, le=50)
    dust_depth_rel: float = Field(0.06, ge=0.0, le=0.5)
    gain_mismatch_rel: float = Field(0.02, ge=0.0, le=0.3, description="Per-camera gain/exposure, rms relative.")
    companding: Literal["sqrt", "linear"] = "sqrt"

    @classmethod
    def profile_defaults(cls, profile: str) -> dict:
        return {"model": "ccd" if profile == "flight" else "ideal"}


@dataclass(frozen=True)
class CameraDefects:
    """Fixed per-camera terms at the rendered resolution: flat field (vignetting, dust, PRNU, gain) and DSNU."""

    flat: np.ndarray  # multiplicative, (H, W) float32
    dsnu_e: np.ndarray  # additive electrons, (H, W) float32


def camera_rng(seed: int, cam_name: str) -> np.random.Generator:
    """The generator of one camera's fixed pattern (depends on the seed and the camera name only)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), _SEED_TAG, zlib.crc32(cam_name.encode())]))


def vignetting(shape: tuple[int, int], corner_rel: float, centre_px: tuple[float, float]) -> np.ndarray:
    """Radial falloff ``1 - corner_rel * (r / r_corner)^2`` about ``centre_px`` (row, col), float32."""
    h, w = shape
    rr, cc = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = ((rr + 0.5 - centre_px[0]) ** 2 + (cc + 0.5 - centre_px[1]) ** 2) / (0.25 * (h * h + w * w))
    return (1.0 - corner_rel * r2).astype(np.float32)


def dust_donut(shape: tuple[int, int], centre_px: tuple[float, float], radius_px: float, depth: float) -> np.ndarray:
    """Transmission of one out-of-focus dust particle: a soft dark ring (``1 - depth`` at its rim), float32."""
    h, w = shape
    rr, cc = np.mgrid[0:h, 0:w].astype(np.float32)
    r = np.hypot(rr + 0.5 - centre_px[0], cc + 0.5 - centre_px[1]) / radius_px
    ring = np.exp(-(((r - 0.8) / 0.25) ** 2)) + 0.5 * np.exp(-((r / 0.6) ** 2))  # rim plus a fainter core
    return (1.0 - depth * np.clip(ring, 0.0, 1.0)).astype(np.float32)


def camera_defects(spec: ImagingSpec, seed: int, cam_name: str, native_px: int) -> CameraDefects:
    """Draw one camera's fixed terms at ``native_px`` (each pixel the mean of ``(1024 / native_px)^2`` sites)."""
    rng = camera_rng(seed, cam_name)
    shape = (native_px, native_px)
    sites = max(1.0, (SENSOR_PX / native_px) ** 2)
    centre = tuple(native_px * (0.5 + 0.08 * rng.standard_normal(2)))
    flat = vignetting(shape, spec.vignetting_corner_rel, centre)  # type: ignore[arg-type]
    for _ in range(spec.dust_spots):
        c = tuple(rng.uniform(0.05, 0.95, 2) * native_px)
        radius = native_px * rng.uniform(0.015, 0.04)
        flat *= dust_donut(shape, c, radius, spec.dust_depth_rel * rng.uniform(0.5, 1.0))  # type: ignore[arg-type]
    gain = 1.0 + spec.gain_mismatch_rel * rng.standard_normal()
    prnu = spec.prnu_rel / np.sqrt(sites) * rng.standard_normal(shape)
    dsnu = spec.dsnu_e / np.sqrt(sites) * rng.standard_normal(shape)
    return CameraDefects((flat * gain * (1.0 + prnu)).astype(np.float32), dsnu.astype(np.float32))


def exposure_scale(radiance: np.ndarray, spec: ImagingSpec) -> float:
    """Relative exposure time putting the ``exposure_percentile`` of ``radiance`` at ``exposure_target_dn``."""
    level = float(np.percentile(radiance, spec.exposure_percentile))
    return spec.exposure_target_dn / DN12_MAX / max(level, 1e-3)


def compand_8bit(dn12: np.ndarray, kind: str) -> np.ndarray:
    """12-bit counts to 8 bits: square-root LUT (MER) or linear scaling."""
    x = np.clip(dn12, 0.0, DN12_MAX) / DN12_MAX
    y = np.sqrt(x) if kind == "sqrt" else x
    return np.rint(255.0 * y).astype(np.uint8)


class ImageFormation:
    """The ``ccd`` image chain for all cameras of one run; per-camera fixed pattern drawn once, lazily."""

    def __init__(self, spec: ImagingSpec, seed: int, binning: int) -> None:
        self.spec, self.seed, self.binning = spec, int(seed), int(binning)
        self._defects: dict[tuple[str, int], CameraDefects] = {}
        self._rng = np.random.default_rng(np.random.SeedSequence([int(seed), _SEED_TAG, 1]))
        self._exposure = 1.0
        self.last_exposure = 1.0  # relative exposure of the last image (diagnostics)

    def reseed_noise(self, seed: int) -> None:
        """Restart the temporal noise stream as a chain built with ``seed`` would start it; the fixed pattern (the
        camera hardware, drawn from the construction seed) is kept. For episodes of one world (the Gymnasium env)."""
        self._rng = np.random.default_rng(np.random.SeedSequence([int(seed), _SEED_TAG, 1]))

    @contextmanager
    def replayed_noise(self) -> Iterator[None]:
        """Images formed inside draw their noise from a copy of the run's noise stream, which is then restored:
        an extra image (e.g. a dataset export) leaves the run's later images, and so its metrics, unchanged."""
        state = self._rng.bit_generator.state
        try:
            yield
        finally:
            self._rng.bit_generator.state = state

    def defects(self, cam_name: str, native_px: int) -> CameraDefects:
        key = (cam_name, native_px)
        if key not in self._defects:
            self._defects[key] = camera_defects(self.spec, self.seed, cam_name, native_px)
        return self._defects[key]

    def form(self, luma_0_255: np.ndarray, cam_name: str) -> np.ndarray:
        """Float luminance at the rasterised resolution -> uint8 image at the output resolution."""
        return compand_8bit(self.dn12(luma_0_255, cam_name), self.spec.companding)

    def dn12(self, luma_0_255: np.ndarray, cam_name: str) -> np.ndarray:
        """Float luminance at the rasterised resolution -> 12-bit counts (float) at the output resolution."""
        s = self.spec
        native = luma_0_255.shape[0]
        d = self.defects(cam_name, native)
        lit = luma_0_255.astype(np.float32) * np.float32(1.0 / 255.0)  # radiance r ...
        lit *= d.flat  # ... through vignetting, dust, gain and PRNU
        if not cam_name.endswith("_right"):  # the left image of a pair (or a single camera) sets the exposure
            pilot = lit[:: max(1, native // 256), :: max(1, native // 256)]  # histogram of a 256x256 pilot
            self._exposure = exposure_scale(pilot, s)
        self.last_exposure = self._exposure
        sites = max(1.0, (SENSOR_PX / native) ** 2)  # photosites each rasterised pixel stands for
        signal_e = lit
        signal_e *= np.float32(self._exposure * s.full_well_e)
        sigma_e = np.maximum(signal_e, 0.0)
        sigma_e += np.float32(s.read_noise_e**2)
        np.sqrt(sigma_e, out=sigma_e)
        electrons = self._rng.standard_normal(signal_e.shape, dtype=np.float32)
        electrons *= sigma_e
        electrons *= np.float32(1.0 / np.sqrt(sites))
        electrons += signal_e
        electrons += d.dsnu_e
        dn12 = electrons
        dn12 *= np.float32(DN12_MAX / s.full_well_e)
        if sites <= 1.0:
            np.rint(dn12, out=dn12)
        np.clip(dn12, 0.0, DN12_MAX, out=dn12)
        if self.binning > 1:
            h, w = dn12.shape
            b = self.binning
            dn12 = dn12.reshape(h // b, b, w // b, b).mean(axis=(1, 3))
        return dn12
