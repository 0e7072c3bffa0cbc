"""``[orbital]``: how the orbital products of a site are made and how wrong they are, with the source of each figure.

Sources:

* HiRISE (McEwen et al. 2007, "Mars Reconnaissance Orbiter's High Resolution Imaging Science Experiment (HiRISE)",
  JGR 112, E05S02): 0.25-0.32 m/pixel from MRO's 255-320 km orbit, a goal of topography "better than 25 cm vertical
  precision"; MRO's orbit is sun-synchronous with a ~3 pm local time ascending node and HiRISE's signal-to-noise
  requirement is better than 100:1 (Delamere et al. 2003, "MRO High Resolution Imaging Science Experiment (HiRISE):
  instrument development"). Hence ``image_px_m`` 0.25, ``local_solar_time_h`` 15.0, ``snr`` 100.
* The optics' blur: a Gaussian point-spread function of ``psf_sigma_px`` 0.5 pixels, i.e. an MTF of 0.29 at Nyquist
  (``exp(-2 pi^2 sigma^2 / 4)``). Assumed: a value in the range of diffraction-limited 0.5 m telescopes at
  HiRISE's pixel scale; HiRISE's as-built MTF is not cited here.
* DEM: HiRISE DTMs are posted at 1-2 m with "vertical precision in the tens of centimeters" (HiRISE DTM team,
  hirise.lpl.arizona.edu/dtm/about.php; McEwen et al. 2007's 25 cm goal). ``dem_sigma_m`` 0.25 with a correlation
  length ``dem_error_correlation_m`` 3 m (stereo matching windows of a few pixels smooth the error; assumed).
* Registration of the map to the site frame: the HiRISE DTM bundle adjustments report a total RMS of 0.22-1.04
  image pixels (HiRISE DTM README files, e.g. Argyre sinuous ridge 0.354 px, Nili Patera 0.222 px); 0.4 px at
  0.25 m is 0.1 m, the default ``registration_sigma_m`` (per axis) and ``registration_sigma_deg`` 0.05 (0.1 m at
  100 m from the map centre). The whole map is shifted and turned by one seeded draw of these.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class OrbitalSpec(BaseModel):
    """The scenario's ``[orbital]`` table (all optional; the defaults are the HiRISE-class figures above)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    image_px_m: float = Field(0.25, ge=0.1, le=2.0, description="Orthoimage pixel, metres (HiRISE: 0.25).")
    dem_px_m: float = Field(1.0, ge=0.25, le=10.0, description="DEM post spacing, metres (HiRISE DTMs: 1-2).")
    local_solar_time_h: float = Field(15.0, ge=7.0, le=17.0, description="Orbiter's local time (MRO: ~15:00).")
    psf_sigma_px: float = Field(0.5, ge=0.0, le=3.0, description="Gaussian optics blur, orthoimage pixels.")
    snr: float = Field(100.0, ge=5.0, le=1000.0, description="Signal-to-noise ratio at the mean signal (>100:1).")
    dem_sigma_m: float = Field(0.25, ge=0.0, le=5.0, description="DEM vertical error std, metres (tens of cm).")
    dem_error_correlation_m: float = Field(3.0, ge=0.0, le=50.0, description="Correlation length of the DEM error.")
    registration_sigma_m: float = Field(0.1, ge=0.0, le=50.0, description="Map offset vs the site frame, per axis.")
    registration_sigma_deg: float = Field(0.05, ge=0.0, le=5.0, description="Map rotation vs the site frame.")
    route_margin_m: float = Field(60.0, ge=10.0, le=500.0, description="Streamed sites: tiles this close to the route.")
    tile_m: float = Field(64.0, ge=16.0, le=1024.0, description="Streamed sites: side of a product tile, metres.")
