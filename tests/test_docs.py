"""The documentation holds together: the README is short, every relative link in it and in
``docs/`` resolves (files, folders and ``#anchors``), the config reference is the schema's own
listing, and every command of ``bench-sim`` is in the README's table."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from bench_sim.cli import app
from bench_sim.workflows.config_cmd import keys_markdown

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").rglob("*.md"))]
MAX_README_LINES = 150
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.M | re.S)


def slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces -> '-'."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    found: set[str] = set()
    for line in FENCE.sub("", path.read_text()).splitlines():
        m = re.match(r"#{1,6}\s+(.*)", line)
        if m:
            base = slug(m.group(1))
            name, n = base, 1
            while name in found:
                name, n = f"{base}-{n}", n + 1
            found.add(name)
    return found


def links(path: Path) -> list[str]:
    return LINK.findall(FENCE.sub("", path.read_text()))


def test_readme_is_short() -> None:
    lines = len((ROOT / "README.md").read_text().splitlines())
    assert lines <= MAX_README_LINES, f"README.md has {lines} lines (at most {MAX_README_LINES})"


def test_slugs_follow_github() -> None:
    assert slug("The default rig (`scenes/paper_rig.toml`)") == "the-default-rig-scenespaper_rigtoml"
    assert slug("Unit slips and misspelled keys") == "unit-slips-and-misspelled-keys"
    assert slug("`bench-sim sweep`: scenario studies") == "bench-sim-sweep-scenario-studies"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(doc: Path) -> None:
    bad = []
    for target in links(doc):
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        file_part, _, anchor = target.partition("#")
        dest = (doc.parent / file_part).resolve() if file_part else doc
        if not dest.exists():
            bad.append(f"{target} (no such file)")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target} (no heading #{anchor} in {dest.name})")
    assert not bad, f"{doc.relative_to(ROOT)}: broken links: {bad}"


def test_docs_index_and_readme_link_every_docs_page() -> None:
    """Every page of docs/ (and every tutorial) is reachable from docs/index.md or the README."""
    linked = set()
    for doc in DOCS:
        for target in links(doc):
            if not re.match(r"[a-z]+:", target):
                linked.add((doc.parent / target.partition("#")[0]).resolve())
    pages = [*sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "docs" / "tutorials").glob("*.py"))]
    orphans = [str(p.relative_to(ROOT)) for p in pages if p.resolve() not in linked and p.name != "index.md"]
    assert not orphans, f"pages no document links to: {orphans}"


def test_config_reference_is_the_schema_listing() -> None:
    page = (ROOT / "docs" / "config-reference.md").read_text()
    assert keys_markdown() in page, "docs/config-reference.md is stale: run `make docs-reference`"


def test_readme_names_every_command() -> None:
    readme = (ROOT / "README.md").read_text()
    names = [c.name or c.callback.__name__ for c in app.registered_commands if c.callback is not None]
    names += [g.name for g in app.registered_groups if g.name]
    missing = [n for n in names if f"`{n}" not in readme]
    assert not missing, f"commands the README's table does not name: {missing}"
