"""The README's library guide runs as written (it is the first thing a new user copies)."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def _block_after(heading: str) -> str:
    text = README.read_text()
    section = text[text.index(heading) :]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_library_guide_runs(capsys):
    code = _block_after("## Library guide")
    namespace: dict = {}
    exec(compile(code, "README.md (library guide)", "exec"), namespace)  # noqa: S102 - our own README
    metrics = namespace["metrics"]
    assert metrics.scenario == "wopmay" and metrics.distance_m > 1.0
    assert namespace["pair"].left_u8.dtype.name == "uint8" and namespace["truth"].position_xyz_m.shape == (3,)
