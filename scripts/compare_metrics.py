"""Check that a code change left every scenario's metrics bit-identical (a refactoring's proof of "no change").

Two steps, each one command:

    python scripts/compare_metrics.py run REF.json [--profile flight] [--fast]   # on the reference commit
    python scripts/compare_metrics.py run NEW.json                               # on the changed code
    python scripts/compare_metrics.py compare REF.json NEW.json                  # exit 1 on any difference

``run`` calls ``rover-sim bench suite --profile P --json FILE`` through the Python it runs under (so it uses the
checkout that Python imports), which runs the catalogue's scenarios at their own seeds and stores, per scenario,
what its ``metrics.json`` holds. ``compare`` compares every key of every scenario's row exactly (floats bit for bit,
NaN equal to NaN) except the wall-clock ones (:data:`IGNORED`); it prints each differing key with both values.
The CLI is the interface, so the same script measures a commit before and after a move of the package's modules.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

IGNORED = frozenset({"timing", "wall_s", "regressions"})  # wall-clock figures and the gate's verdict on them


def run(out: Path, profiles: list[str], fast: bool) -> int:
    """Run the catalogue through the CLI of the interpreter's checkout; the suite's exit code (1 = a scenario failed
    its criterion, which does not stop the comparison)."""
    cmd = [sys.executable, "-m", "rover_sim.cli.main", "bench", "suite", "--json", str(out)]
    for p in profiles:
        cmd += ["--profile", p]
    if fast:
        cmd.append("--fast")
    print("+", " ".join(cmd), flush=True)
    code = subprocess.call(cmd)
    if not out.is_file():
        print(f"{out}: the suite wrote no JSON (exit {code})", file=sys.stderr)
        return 2
    return 0


def _rows(path: Path) -> dict[tuple[str, str], dict]:
    data = json.loads(Path(path).read_text())
    if not isinstance(data, list):
        raise SystemExit(f"{path}: expected a bench suite --json list of rows")
    return {(r.get("profile", "?"), r["scenario"]): r for r in data}


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or a == b
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def differences(ref: dict[tuple[str, str], dict], new: dict[tuple[str, str], dict]) -> list[str]:
    """Every (profile, scenario, key) whose value differs, and every scenario present on one side only."""
    out = [f"{p}/{s}: only in the reference" for p, s in sorted(ref.keys() - new.keys())]
    out += [f"{p}/{s}: only in the new run" for p, s in sorted(new.keys() - ref.keys())]
    for key in sorted(ref.keys() & new.keys()):
        a, b = ref[key], new[key]
        for k in sorted((a.keys() | b.keys()) - IGNORED):
            if k not in a or k not in b or not _same(a[k], b[k]):
                out.append(f"{key[0]}/{key[1]}: {k}: {a.get(k, '<missing>')!r} != {b.get(k, '<missing>')!r}")
    return out


def compare(ref_path: Path, new_path: Path) -> int:
    ref, new = _rows(ref_path), _rows(new_path)
    diffs = differences(ref, new)
    n_keys = sum(len(r.keys() - IGNORED) for k, r in ref.items() if k in new)
    if diffs:
        print("\n".join(diffs))
        print(f"DIFFERENT: {len(diffs)} difference(s) over {len(ref)} reference rows")
        return 1
    print(f"IDENTICAL: {len(ref)} scenario rows, {n_keys} keys (ignored: {', '.join(sorted(IGNORED))})")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the catalogue (rover-sim bench suite) and store its rows")
    r.add_argument("out", type=Path)
    r.add_argument("--profile", action="append", choices=("flight", "ideal"), help="default: flight")
    r.add_argument("--fast", action="store_true", help="only the CI subset (scenarios with fast = true)")
    c = sub.add_parser("compare", help="exit 1 unless every non-timing metric is identical")
    c.add_argument("reference", type=Path)
    c.add_argument("new", type=Path)
    a = ap.parse_args(argv)
    if a.cmd == "run":
        return run(a.out, a.profile or ["flight"], a.fast)
    return compare(a.reference, a.new)


if __name__ == "__main__":
    sys.exit(main())
