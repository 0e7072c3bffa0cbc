"""Step 2: match the local map with the orbital map by masked normalised cross-correlation over the search region.

For a template ``T`` seen only where the mask ``M`` is set, the NCC at every shift comes from three FFT
correlations (Padfield 2012, "Masked object registration in the Fourier domain", IEEE TIP 21(5)): ``sum T' I``,
``sum M I`` and ``sum M I^2`` with ``T'`` the zero-mean, unit-norm template on its mask. The search is exhaustive
over the prior's position uncertainty (every map pixel) and its yaw uncertainty (``yaw_step_deg``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import fftconvolve


def masked_ncc(image: np.ndarray, template: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """NCC of ``template`` (valid where ``mask``) at every shift fully inside ``image`` ('valid' correlation):
    ``out[r, c]`` compares ``template`` with ``image[r:r+h, c:c+w]``."""
    m = mask.astype(np.float64)
    n = float(m.sum())
    t = np.where(mask, template - (template * m).sum() / max(n, 1.0), 0.0)
    t /= max(float(np.sqrt((t * t).sum())), 1e-12)
    flip = (slice(None, None, -1), slice(None, None, -1))
    num = fftconvolve(image, t[flip], mode="valid")
    s1 = fftconvolve(image, m[flip], mode="valid")
    s2 = fftconvolve(image * image, m[flip], mode="valid")
    var = np.maximum(s2 - s1 * s1 / max(n, 1.0), 1e-12)
    return np.clip(num / np.sqrt(var), -1.0, 1.0)


@dataclass(frozen=True)
class Peak:
    """The best hypothesis of a score volume (yaw index, row, column) with sub-pixel refinement."""

    k: int
    r: int
    c: int
    score: float
    dr: float  # sub-pixel offsets (pixels / yaw steps)
    dc: float
    dk: float
    hessian_px: np.ndarray  # (2, 2) second derivatives of the score in (row, col) at the peak
    d2_yaw: float  # second derivative of the score in yaw steps


def refine_peak(scores: np.ndarray) -> Peak:
    """Best cell of ``scores`` (n_yaw, H, W) and a quadratic fit around it (rows, columns, yaw)."""
    k, r, c = (int(v) for v in np.unravel_index(int(np.nanargmax(scores)), scores.shape))
    s = scores[k]
    H, W = s.shape
    r1, c1 = min(max(r, 1), H - 2), min(max(c, 1), W - 2)
    w = s[r1 - 1 : r1 + 2, c1 - 1 : c1 + 2]
    drr = w[2, 1] - 2 * w[1, 1] + w[0, 1]
    dcc = w[1, 2] - 2 * w[1, 1] + w[1, 0]
    drc = 0.25 * (w[2, 2] - w[2, 0] - w[0, 2] + w[0, 0])
    g = np.array([0.5 * (w[2, 1] - w[0, 1]), 0.5 * (w[1, 2] - w[1, 0])])
    Hm = np.array([[drr, drc], [drc, dcc]])
    try:
        off = -np.linalg.solve(Hm, g) if np.all(np.linalg.eigvalsh(Hm) < 0) else np.zeros(2)
    except np.linalg.LinAlgError:
        off = np.zeros(2)
    off = np.clip(off, -1.0, 1.0) + np.array([r1 - r, c1 - c]) * 0.0
    d2k, dk = 0.0, 0.0
    if 0 < k < scores.shape[0] - 1:
        a, b, cc = scores[k - 1, r, c], scores[k, r, c], scores[k + 1, r, c]
        d2k = float(a - 2 * b + cc)
        dk = float(np.clip(-0.5 * (cc - a) / d2k, -0.5, 0.5)) if d2k < 0 else 0.0
    return Peak(k, r, c, float(s[r, c]), float(off[0]), float(off[1]), dk, Hm, d2k)


def lobe_area_px(score: np.ndarray, r: int, c: int) -> int:
    """Pixels of the connected region around ``(r, c)`` scoring at least half the peak (the correlation lobe)."""
    from scipy.ndimage import label

    above = score >= 0.5 * score[r, c]
    lab, _ = label(above)
    return max(1, int((lab == lab[r, c]).sum()))


def best_elsewhere(scores: np.ndarray, r: int, c: int, exclusion_px: float) -> tuple[float, tuple[int, int, int]]:
    """The best score (any yaw) farther than ``exclusion_px`` from ``(r, c)``, and where it is."""
    _, H, W = scores.shape
    rr, cc = np.ogrid[:H, :W]
    far = (rr - r) ** 2 + (cc - c) ** 2 > exclusion_px**2
    masked = np.where(far[None], scores, -np.inf)
    idx = np.unravel_index(int(np.argmax(masked)), masked.shape)
    return float(masked[idx]), (int(idx[0]), int(idx[1]), int(idx[2]))
