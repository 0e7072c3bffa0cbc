"""Global localisation against orbital products: a navcam panorama matched with an orthoimage and a DEM.

Entry point: :class:`OrbitalLocalizer` (the built-in :class:`nav.protocols.GlobalLocalizer`); the data it takes:
:class:`PanoramaView` (a rectified pair and its calibrated rig) and :class:`OrbitalMap`.
"""

from nav.globalloc.localizer import GlobalLocResult, OrbitalLocalizer, decide
from nav.globalloc.localmap import PanoramaView
from nav.globalloc.maps import OrbitalMap, Raster
from nav.globalloc.params import GlobalLocParams

__all__ = ["GlobalLocParams", "GlobalLocResult", "OrbitalLocalizer", "OrbitalMap", "PanoramaView", "Raster", "decide"]
