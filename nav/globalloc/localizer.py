"""The built-in global localiser: a navcam panorama against the orbital orthoimage and DEM.

Method (after Mars 2020's Mars Global Localization: a navcam panorama orthorectified and matched to the orbital
image; the rocks and their shadows that both see carry the match, as in Li et al.'s rock-based localisation):

1. local map: stereo points of the panorama in a level frame (:mod:`nav.globalloc.localmap`);
2. for every yaw in the prior's +-3 sigma: grid the points into an orthomosaic at the orbital pixel, blur it by the
   orbital optics' PSF, remove its local mean (brightness differences of exposure, shading and time of day), and
   correlate it with the equally high-passed orbital image over the prior's +-3 sigma of position
   (:func:`nav.globalloc.match.masked_ncc`);
3. the best peak, refined to sub-pixel and sub-step, is the fix; its covariance comes from the peak's curvature
   scaled by the match's residual and its effective number of independent samples, plus the map's stated
   registration error;
4. refusal (:func:`decide`): the fix is returned only if the peak is significant against the search's null
   distribution (Bonferroni over independent hypotheses at ``false_alarm``), unique (it beats the best hypothesis
   more than ``exclusion_m`` away by ``uniqueness_sigmas`` standard errors of Fisher's z), precise (1-sigma major
   axis below ``max_sigma_m``) and consistent with the orbital DEM (chi-square of the local elevation's residual).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.stats import norm

from nav.globalloc.localmap import LocalPoints, PanoramaView, grid_points, highpass, panorama_points, rotate_xy
from nav.globalloc.maps import OrbitalMap
from nav.globalloc.match import best_elsewhere, lobe_area_px, masked_ncc, refine_peak
from nav.globalloc.params import GlobalLocParams


@dataclass
class GlobalLocResult:
    """A global fix or a refusal. ``status`` "ok": ``xy_yaw`` (x, y [m], yaw [rad], map frame) and ``covariance``
    (3x3 over them) are set; any other status is a refusal with a ``reason``."""

    status: str
    reason: str = ""
    xy_yaw: np.ndarray | None = None
    covariance: np.ndarray | None = None
    diagnostics: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def yaw_of(R: np.ndarray) -> float:
    return math.atan2(R[1, 0], R[0, 0])


class OrbitalLocalizer:
    """The built-in :class:`nav.protocols.GlobalLocalizer` (see the module docstring)."""

    def __init__(self, params: GlobalLocParams | None = None) -> None:
        self.params = params or GlobalLocParams()

    def localize(
        self,
        views: list[PanoramaView],
        R_world_rover: np.ndarray,
        prior_xy_yaw: np.ndarray,
        prior_covariance: np.ndarray,
        orbital: OrbitalMap,
    ) -> GlobalLocResult:
        t0 = time.process_time()
        p = self.params
        pts = panorama_points(views, R_world_rover, p)
        t_stereo = time.process_time() - t0
        res = self.match(pts, np.asarray(prior_xy_yaw, float), np.asarray(prior_covariance, float), orbital)
        res.diagnostics.update(stereo_cpu_s=t_stereo, cpu_s=time.process_time() - t0, n_points=len(pts.grey))
        return res

    # ------------------------------------------------------------------------------------------------ matching
    def match(self, pts: LocalPoints, prior: np.ndarray, cov: np.ndarray, orbital: OrbitalMap) -> GlobalLocResult:
        p = self.params
        px = orbital.image.px_m
        sig_xy = math.sqrt(max(cov[0, 0], cov[1, 1]))
        sig_yaw = math.sqrt(cov[2, 2])
        search_m = p.search_sigmas * sig_xy
        half_t = p.max_range_m + 2 * px
        crop = orbital.crop(prior[:2], search_m + half_t)
        img = crop.image.values.astype(np.float64)
        if min(img.shape) < 8:
            return GlobalLocResult("refused", "the orbital map does not cover the prior's search region")
        valid_img = np.isfinite(img)
        img_n = img / max(float(np.nanmedian(img)), 1e-9)
        sigma_px = p.highpass_sigma_m / px
        img_hp = highpass(img_n, valid_img, sigma_px)
        n_yaw = max(1, int(math.ceil(p.search_sigmas * math.degrees(sig_yaw) / p.yaw_step_deg)))
        yaws = np.arange(-n_yaw, n_yaw + 1) * math.radians(p.yaw_step_deg)
        scores, n_valid, area_t = [], 0, 0
        for dyaw in yaws:
            g = grid_points(rotate_xy(pts.xyz_m, dyaw), pts.grey, px, half_t)
            seen = g.counts > 0
            tmpl = np.where(seen, g.values, 0.0)
            if orbital.psf_sigma_px > 0:  # the orbital optics' blur, over the seen cells only
                w = cv2.GaussianBlur(seen.astype(np.float64), (0, 0), orbital.psf_sigma_px)
                tmpl = np.where(seen, cv2.GaussianBlur(tmpl, (0, 0), orbital.psf_sigma_px) / np.maximum(w, 1e-6), 0)
            t_hp = highpass(tmpl, seen, sigma_px)
            scores.append(masked_ncc(img_hp, t_hp, seen))
            n_valid, area_t = int(seen.sum()), g.values.shape[0]
        vol = np.stack(scores)
        if n_valid < p.min_cells:
            return GlobalLocResult("refused", f"too little ground seen ({n_valid} cells < {p.min_cells})")
        pk = refine_peak(vol)
        # where the rover is for the best shift: the template's centre cell
        n_half = (area_t - 1) // 2
        x0, y0 = crop.image.x0_m, crop.image.y0_m
        fix_x = x0 + (pk.c + pk.dc + n_half) * px
        fix_y = y0 + (pk.r + pk.dr + n_half) * px
        dyaw = (pk.k + pk.dk - n_yaw) * math.radians(p.yaw_step_deg)
        xy_yaw = np.array([fix_x, fix_y, prior[2] + dyaw])
        lobe = lobe_area_px(vol[pk.k], pk.r, pk.c)
        n_eff = max(n_valid / lobe, 4.0)
        second, where2 = best_elsewhere(vol, pk.r, pk.c, p.exclusion_m / px)
        flat = vol.ravel()
        med = float(np.median(flat))
        mad = 1.4826 * float(np.median(np.abs(flat - med)))
        n_hyp = max(vol.size / lobe, 1.0)
        diag = dict(peak=pk.score, second=second, median=med, mad=mad, n_eff=n_eff, lobe_px=lobe, n_cells=n_valid,
                    n_hypotheses=n_hyp, second_at_m=float(np.hypot(where2[1] - pk.r, where2[2] - pk.c) * px))
        diag["candidate_xy_yaw"] = [float(v) for v in xy_yaw]  # the best hypothesis, also when refused
        cov_fix = self.covariance(pk, n_eff, px, orbital)
        diag["sigma_major_m"] = float(math.sqrt(max(np.linalg.eigvalsh(cov_fix[:2, :2]).max(), 0.0)))
        dem_chi2 = self.dem_check(pts, xy_yaw, prior, orbital)
        diag.update(dem_chi2)
        status, reason = decide(diag, p)
        if status != "ok":
            return GlobalLocResult(status, reason, diagnostics=diag)
        return GlobalLocResult("ok", "", xy_yaw, cov_fix, diagnostics=diag)

    def covariance(self, pk: object, n_eff: float, px: float, orbital: OrbitalMap) -> np.ndarray:
        """Position and yaw covariance of the fix: the NCC peak's curvature as a likelihood (``n_eff`` samples, the
        residual ``1 - peak`` as the noise) plus the map's stated registration error."""
        p = self.params
        scale = max(1.0 - pk.score, 1e-3) / n_eff  # type: ignore[attr-defined]
        H = -np.asarray(pk.hessian_px)  # type: ignore[attr-defined]
        cov = np.full((3, 3), 0.0)
        try:
            ev = np.linalg.eigvalsh(H)
            c_rc = np.linalg.inv(H) * scale if ev.min() > 1e-9 else np.eye(2) * 1e6
        except np.linalg.LinAlgError:
            c_rc = np.eye(2) * 1e6
        cov[0, 0], cov[1, 1] = c_rc[1, 1] * px**2, c_rc[0, 0] * px**2  # (row, col) -> (y, x)
        cov[0, 1] = cov[1, 0] = c_rc[0, 1] * px**2
        cov[:2, :2] += np.eye(2) * orbital.registration_sigma_m**2
        d2k = -float(pk.d2_yaw)  # type: ignore[attr-defined]
        step = math.radians(p.yaw_step_deg)
        cov[2, 2] = (scale / d2k * step**2 if d2k > 1e-9 else step**2) + orbital.registration_sigma_rad**2
        return cov

    def dem_check(self, pts: LocalPoints, xy_yaw: np.ndarray, prior: np.ndarray, orbital: OrbitalMap) -> dict:
        """Residual of the local elevation (1 m posts with enough points) against the orbital DEM at the fix, after
        the unknown height offset; returned as the mean chi-square and its number of posts."""
        p, dem = self.params, orbital.dem
        g = grid_points(rotate_xy(pts.xyz_m, xy_yaw[2] - prior[2]), pts.xyz_m[:, 2], dem.px_m, p.max_range_m)
        ok = g.counts >= 20
        if ok.sum() < 10:
            return {"dem_chi2": float("nan"), "dem_posts": int(ok.sum())}
        rr, cc = np.nonzero(ok)
        x = xy_yaw[0] + g.x0_m + cc * dem.px_m
        y = xy_yaw[1] + g.y0_m + rr * dem.px_m
        z_map = dem.sample(x, y)
        fin = np.isfinite(z_map)
        res = g.values[rr, cc][fin] - z_map[fin]
        res -= np.median(res)
        var = orbital.dem_sigma_m**2 + p.dem_stereo_sigma_m**2
        return {"dem_chi2": float(np.mean(res * res) / var), "dem_posts": int(fin.sum())}


def decide(d: dict, p: GlobalLocParams) -> tuple[str, str]:
    """Accept or refuse a match from its statistics (see the module docstring, step 4)."""
    z_crit = float(norm.isf(p.false_alarm / d["n_hypotheses"]))
    z = (d["peak"] - d["median"]) / max(d["mad"], 1e-9)
    d["z"], d["z_crit"] = z, z_crit
    if z < z_crit:
        return "refused", f"no significant match (peak {z:.1f} sigma < {z_crit:.1f})"
    se = math.sqrt(2.0 / max(d["n_eff"] - 3.0, 1.0))
    margin = (math.atanh(min(d["peak"], 0.999999)) - math.atanh(min(max(d["second"], -0.999999), 0.999999))) / se
    d["uniqueness"] = margin
    if margin < p.uniqueness_sigmas:
        return "refused", f"ambiguous: a second match {d['second_at_m']:.1f} m away within {margin:.1f} std errors"
    if d["sigma_major_m"] > p.max_sigma_m:
        return "refused", f"imprecise: 1-sigma {d['sigma_major_m']:.2f} m > {p.max_sigma_m} m"
    chi2, n = d.get("dem_chi2", float("nan")), d.get("dem_posts", 0)
    if np.isfinite(chi2) and n > 0 and chi2 > 1.0 + p.dem_chi2_sigmas * math.sqrt(2.0 / n):
        return "refused", f"inconsistent with the orbital DEM (mean chi-square {chi2:.2f} over {n} posts)"
    return "ok", ""
