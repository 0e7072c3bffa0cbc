"""How the rover's cameras are rendered (:class:`RenderConfig`) and the simple image noise of the ideal profile
(:class:`ImageNoise`)."""

from __future__ import annotations

from dataclasses import dataclass

from rover_sim.render.imaging import ImagingSpec


@dataclass(frozen=True)
class ImageNoise:
    """Sensor noise: Gaussian read noise in 12-bit counts, then 12-bit quantisation, then scaling to 8 bits."""

    read_noise_dn12: float = 3.0  # rms counts of a 0..4095 signal (about 0.19 grey levels of 8 bits)
    seed: int = 0


@dataclass(frozen=True)
class RenderConfig:
    """How images are rendered. Defaults: fast navigation images (direct 256x256, shadows on)."""

    resolution_px: int = 256  # output image side (square images)
    binning: int = 1  # 1: render at resolution_px; 4: render 4x larger and average 4x4 blocks (MER style)
    shadows: bool = True
    shadow_map_px: int = 2048  # shadow-map side; with the 16 m wide shadow box: 8 mm per texel (1024: 20 % faster)
    shadow_half_extent_m: float = 8.0  # half width of the shadowed square (perpendicular to the sunlight), navcams
    hazcam_shadow_half_extent_m: float = 6.0  # the same for the hazcams, which look near: 6 mm texels at 2048
    # Terrain self-shadowing (crater rims, ripple crests at low sun). Off by default: the terrain then only
    # receives shadows (of the rover and rocks) and is shaded by its slope, which at the scenarios' 25-60 deg
    # sun loses little, and the shadow pass no longer rasterises the ground: half the cost of a shadowed pair.
    terrain_casts_shadows: bool = False
    # tessellation of the rover's cylinders/capsules (MuJoCo defaults 28, 16): 24 slices keep a wheel's facets
    # within 1.1 mm of the true cylinder (0.4 % of the depth at the hazcams' 0.26 m)
    builtin_slices: int = 24
    builtin_stacks: int = 8
    multisamples: int = 0  # MSAA samples per pixel (0 = off; 4 costs about 25 % more at 256x256)
    skybox: bool = True  # draw the sky gradient where no terrain is seen (cheap)
    terrain_tile_m: float = 1.6  # side of the render-only terrain tiles (culling and level-of-detail unit)
    max_terrain_tiles: int = 2500  # larger terrains get larger tiles
    cull: bool = True  # hide terrain tiles and rocks outside both cameras' view (and their shadow volume)
    lod: bool = True  # draw distant tiles coarser while their height error stays under lod_tolerance_px
    lod_tolerance_px: float = 0.25  # largest height error of a tile level, in pixels at the tile's distance
    lod_max_depth_error: float = 0.005  # ... and at most this fraction of the range along grazing rays
    sun_intensity: float = 1.3  # diffuse strength of the sun (above 1: exposure gain; GL clamps per channel)
    sky_ambient: float = 0.5  # uniform ambient light standing in for the dusty sky
    noise: ImageNoise | None = None
    imaging: ImagingSpec | None = None  # the ``ccd`` chain (flight profile) replaces ``noise``; None/ideal: as before
    imaging_seed: int = 0

    def __post_init__(self) -> None:
        if self.resolution_px < 8 or self.binning < 1:
            raise ValueError(f"resolution_px must be >= 8 and binning >= 1, got {self.resolution_px}, {self.binning}")
        if min(self.shadow_half_extent_m, self.hazcam_shadow_half_extent_m, self.terrain_tile_m) <= 0:
            raise ValueError("shadow extents and terrain_tile_m must be positive")

    def shadow_half_extent_for(self, cam_name: str) -> float:
        return self.hazcam_shadow_half_extent_m if cam_name.startswith("hazcam") else self.shadow_half_extent_m

    @property
    def native_px(self) -> int:
        """Side of the image actually rasterised (before binning)."""
        return self.resolution_px * self.binning
