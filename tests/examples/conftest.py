"""Make ``examples`` (repo root) and the synthetic-scene helpers of ``tests/nav/vo_synth.py`` importable."""

import sys
from pathlib import Path

_HERE = Path(__file__).resolve().parent
for _p in (_HERE.parents[1], _HERE.parent / "nav"):  # repo root, tests/nav
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))
