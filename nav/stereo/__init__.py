"""Temporary shim: the module is being split into this package (next commit)."""

from nav.stereo.pipeline import *  # noqa: F403
