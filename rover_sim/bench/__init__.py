"""Benchmarks: each prints a markdown table and can write JSON. Speed lives here, not in tests."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def write_json(json_path: str | Path | None, data: Any) -> None:
    """Write a benchmark's machine-readable result (no-op when ``json_path`` is None)."""
    if json_path:
        path = Path(json_path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(data, indent=2))
