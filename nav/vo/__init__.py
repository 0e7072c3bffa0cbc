"""Temporary shim: the module is being split into this package (next commit)."""

from nav.vo.pipeline import *  # noqa: F403
from nav.vo.pipeline import __all__  # noqa: F401
