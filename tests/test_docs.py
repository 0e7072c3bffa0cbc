"""The documentation: generated pages match their sources, and the README's and the site's links resolve."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def _gen_docs():
    spec = importlib.util.spec_from_file_location("gen_docs", ROOT / "scripts" / "gen_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_generated_pages_are_current():
    """``docs/scenarios.md``, ``docs/cli.md`` and ``docs/benchmarks/tables.md`` are what scripts/gen_docs.py writes
    from the scenarios, the CLI and the committed JSON (run it after changing any of them)."""
    gen = _gen_docs()
    for path, make in gen.PAGES.items():
        assert path.read_text() == make(), f"{path.relative_to(ROOT)} is stale: run python scripts/gen_docs.py"


def test_every_scenario_and_command_is_in_the_generated_pages():
    gen = _gen_docs()
    catalogue = gen.scenarios_page()
    for toml in (ROOT / "scenarios").glob("*.toml"):
        assert f"## {toml.stem}" in catalogue
    cli = gen.cli_page()
    for command in ("run", "view", "export", "bench suite", "bench report", "scenarios"):
        assert f"`rover-sim {command}`" in cli


def test_readme_is_a_front_door():
    text = README.read_text()
    assert len(text.splitlines()) <= 300
    assert "make demo" in text and "make test" in text
    assert text.index("make demo") < text.index("pip install")


def test_readme_links_resolve():
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README.read_text()):
        if not target.startswith(("http://", "https://")):
            assert (ROOT / target).exists(), f"README links to a missing file: {target}"


def test_site_navigation_lists_existing_pages():
    config = (ROOT / "mkdocs.yml").read_text()
    docs = ROOT / re.search(r"^docs_dir: (\S+)$", config, re.M).group(1)
    nav = config[config.index("\nnav:") :]
    listed = set(re.findall(r"^\s+- [^:]+: (\S+\.md)$", nav, re.M))
    assert all((docs / p).exists() for p in listed), sorted(p for p in listed if not (docs / p).exists())
    on_disk = {str(p.relative_to(docs)) for p in docs.rglob("*.md")}
    assert on_disk == listed, f"pages not in mkdocs.yml nav: {sorted(on_disk - listed)}"
