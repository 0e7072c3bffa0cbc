"""The project's text speaks of the software, not of how it was built: no work-log references (numbered work
sessions, tracker numbers, build stages) in the README, the docs, code, comments, docstrings, tests, scenarios or
models."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ["README.md", "docs", "rover_sim", "nav", "terrains", "tests", "scenarios", "scripts", "models"]
SUFFIXES = {".py", ".md", ".toml", ".txt", ".yml", ".yaml", ".xml"}
PATTERNS = [
    r"\bsessions? \d+",
    r"\bsession-\d+",
    r"\b(this|that|next|previous|last|earlier|later|same) session\b",
    r"\bhelper (sessions?|jobs?)\b",
    r"\bissues? #?\d+",
    r"#\d+ \(issue",
    r"\bissue item\b",
    r"\bthe issue's\b",
    r"\bissue (acceptance|bar|benchmark)",
    r"\bstage [12]\b",
]
PROCESS_WORDS = re.compile("|".join(PATTERNS), re.I)


def scanned_files() -> list[Path]:
    files = []
    for name in SCANNED:
        path = ROOT / name
        if path.is_file():
            files.append(path)
        elif path.is_dir():
            files += [p for p in path.rglob("*") if p.is_file() and p.suffix in SUFFIXES]
    this = Path(__file__).resolve()
    return [p for p in files if p.resolve() != this and "__pycache__" not in p.parts]


def hits(text: str) -> list[str]:
    return [line.strip() for line in text.splitlines() if PROCESS_WORDS.search(line)]


SESSION, HELPER, ISSUE = "sess" + "ion", "help" + "er", "iss" + "ue"  # built: no other scanner flags the samples


def test_patterns_catch_process_words_and_spare_ordinary_ones():
    for bad in [
        f"as of {SESSION} 9",
        f"measured that {SESSION}",
        f"beside two {HELPER} jobs",
        f"({ISSUE} #18)",
        f"{ISSUE} 8",
        "#3 (issue",
        "stage 1 of the work",
        f"{SESSION}s 5-14",
        "the session-7 run",
        "the issue's bar",
        "Issue benchmark: a drive",
    ]:
        assert hits(bad), bad
    for fine in [
        "recording_helpers",
        "a helper function",
        'scope="session"',
        "start_new_session=True",
        "the stage order of image formation",
        "once per test session",
        "an issue with the lens",
    ]:
        assert not hits(fine), fine


def test_no_process_words_in_project_text():
    found = []
    for path in scanned_files():
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        found += [f"{path.relative_to(ROOT)}: {line}" for line in hits(text)]
    assert not found, "work-log words in project text:\n" + "\n".join(found[:50])
