"""Make the synthetic-scene helpers of ``tests/nav/vo_synth.py`` importable."""

import sys
from pathlib import Path

_NAV_TESTS = Path(__file__).resolve().parents[2] / "nav"
if str(_NAV_TESTS) not in sys.path:
    sys.path.insert(0, str(_NAV_TESTS))
