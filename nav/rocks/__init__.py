"""Temporary shim: the module is being split into this package (next commit)."""

from nav.rocks.extract import *  # noqa: F403
