"""Procedural planetary terrain synthesis (pure numpy/scipy/trimesh/pydantic; no MuJoCo, no rerun).

A :class:`TerrainRecipe` (typed, validated) plus a seed gives a :class:`Terrain` via :func:`synthesize`: a
heightfield on a centred grid in the MuJoCo hfield convention, a material map (sand / bedrock / mixed) and
analytic rocks (the four rock models of Li et al.). :func:`albedo_texture` paints the ground for the renderer.

    >>> from terrains import TerrainRecipe, SlopeSpec, synthesize
    >>> terrain = synthesize(TerrainRecipe(size_m=(10, 10), slope=SlopeSpec(slope_deg=17)), seed=3)
    >>> terrain.height_at(0.0, 0.0)  # doctest: +SKIP
"""

from terrains.appearance import albedo_texture, rock_albedo, texture_rgb_u8
from terrains.errors import InvalidRockError, InvalidTerrainError, TerrainError, TerrainFileError
from terrains.recipe import (
    CraterSpec,
    Disc,
    DriftRippleSpec,
    ExplicitRockSpec,
    MaterialSpec,
    RippleSpec,
    RockShape,
    RockSpec,
    RoughnessSpec,
    SlopeSpec,
    TerrainRecipe,
)
from terrains.regolith import albedo_tile
from terrains.rock_shapes import IRREGULAR_FORMS, IrregularRock, rock_class
from terrains.synth import synthesize
from terrains.terrain import Material, Rock, Terrain

__all__ = [
    "CraterSpec",
    "Disc",
    "DriftRippleSpec",
    "ExplicitRockSpec",
    "IRREGULAR_FORMS",
    "IrregularRock",
    "rock_class",
    "InvalidRockError",
    "InvalidTerrainError",
    "Material",
    "MaterialSpec",
    "RippleSpec",
    "Rock",
    "RockShape",
    "RockSpec",
    "RoughnessSpec",
    "SlopeSpec",
    "Terrain",
    "TerrainError",
    "TerrainFileError",
    "TerrainRecipe",
    "albedo_texture",
    "albedo_tile",
    "rock_albedo",
    "synthesize",
    "texture_rgb_u8",
]
