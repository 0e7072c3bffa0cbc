"""Every exception the ``terrains`` package raises, each message saying how to fix the problem.

Recipe problems are reported by pydantic as :class:`pydantic.ValidationError` (the location names the field);
the classes here cover objects built directly in code (rocks, terrains from arrays) and terrain files.
"""

from __future__ import annotations


class TerrainError(ValueError):
    """Base class of the package's errors (a ``ValueError``, so callers may catch either)."""


class InvalidRockError(TerrainError):
    """A :class:`terrains.Rock` with impossible geometry (non-positive size, unknown shape, ...)."""


class InvalidTerrainError(TerrainError):
    """A :class:`terrains.Terrain` whose arrays disagree in shape or type, or whose cell size is not > 0."""


class TerrainFileError(TerrainError):
    """A ``.npz`` file not written by :meth:`terrains.Terrain.save` (or by another file version)."""
