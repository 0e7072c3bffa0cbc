"""Temporary shim: the module is being split into this package (next commit)."""

from nav.gestalt.map import *  # noqa: F403
