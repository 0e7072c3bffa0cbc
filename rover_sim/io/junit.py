"""JUnit XML for CI (``--junit PATH`` on ``rover-sim run`` and every benchmark): one ``<testcase>`` per scenario
or benchmark case, a ``<failure>`` whose message is the unmet criterion with the measured value. Stdlib only."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Case:
    """One test case. ``failure``: why it failed (None: passed); ``error``: the case did not run to completion
    (JUnit's ``<error>``, e.g. physics diverged or a plugin raised)."""

    name: str
    classname: str
    failure: str | None = None
    error: str | None = None
    time_s: float = 0.0
    output: str = ""


def case(name: str, classname: str, ok: bool, message: str, time_s: float = 0.0) -> Case:
    """A passing case, or a failing one whose message is ``message``."""
    return Case(name, classname, None if ok else message, None, time_s)


def error_case(suite: str, message: str) -> Case:
    """The one case of a command that never ran (bad input) or was stopped (interrupted): ``message`` says why."""
    name = suite.replace(" ", ".")
    return Case(name, name, failure=message, error=message)


def write_junit(path: str | Path | None, suite: str, cases: list[Case]) -> None:
    """Write ``cases`` as one ``<testsuite>`` in a ``<testsuites>`` document (no-op when ``path`` is None)."""
    if not path:
        return
    failures = sum(c.failure is not None and c.error is None for c in cases)
    errors = sum(c.error is not None for c in cases)
    total = sum(c.time_s for c in cases)
    root = ET.Element("testsuites", name="rover-sim", tests=str(len(cases)), failures=str(failures),
                      errors=str(errors), time=f"{total:.3f}")  # fmt: skip
    ts = ET.SubElement(root, "testsuite", name=suite, tests=str(len(cases)), failures=str(failures),
                       errors=str(errors), skipped="0", time=f"{total:.3f}")  # fmt: skip
    for c in cases:
        tc = ET.SubElement(ts, "testcase", name=c.name, classname=c.classname, time=f"{c.time_s:.3f}")
        if c.error is not None:
            ET.SubElement(tc, "error", message=c.error, type="RunError").text = c.error
        elif c.failure is not None:
            ET.SubElement(tc, "failure", message=c.failure, type="CriterionFailed").text = c.failure
        if c.output:
            ET.SubElement(tc, "system-out").text = c.output
    tree = ET.ElementTree(root)
    ET.indent(tree)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tree.write(p, encoding="utf-8", xml_declaration=True)


def scenario_case(metrics: dict, classname: str, name: str | None = None) -> Case:
    """A scenario run (``metrics.json`` as a dict): failure = ``reason``; a run that did not complete is an error."""
    reason = str(metrics.get("reason", ""))
    t = float(metrics.get("wall_s") or 0.0)
    nm = name or str(metrics.get("scenario", "?"))
    if metrics.get("passed"):
        return Case(nm, classname, time_s=t)
    if reason.startswith("run did not complete"):
        return Case(nm, classname, failure=reason, error=reason, time_s=t)
    return Case(nm, classname, failure=reason, time_s=t)
