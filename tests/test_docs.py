"""The user guide holds together: README.md within its length, every relative link in README.md
and docs/ resolves, and every file in docs/ (figures, tables, results) is named in docs/README.md
with the command that wrote it or as a hand-written guide."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


def _markdown() -> list[Path]:
    return [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]


def test_the_readme_is_a_guide_not_a_notebook():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 350, f"README.md has {len(lines)} lines (at most 350: results go to docs/)"
    text = "\n".join(lines)
    # what .ci/run and a new user rely on
    assert "./scripts/test" in text and "./scripts/demo" in text
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")


def test_every_relative_link_resolves():
    bad = []
    for md in _markdown():
        for target in LINK.findall(md.read_text()):
            if "://" in target or target.startswith("mailto:"):
                continue
            if not (md.parent / target).exists():
                bad.append(f"{md.relative_to(ROOT)} -> {target}")
    assert not bad, bad


def test_every_file_in_docs_names_what_wrote_it():
    index = (DOCS / "README.md").read_text()
    missing = []
    for p in sorted(DOCS.rglob("*")):
        if not p.is_file() or p.name == "README.md":
            continue
        rel = p.relative_to(DOCS).as_posix()
        # results/sitl-*.json and calibration-*.md are named by pattern
        named = rel in index or any(
            re.fullmatch(pat.replace("*", ".*").replace("<...>", ".*"), rel)
            for pat in re.findall(r"`([^`]*[*<][^`]*)`", index)
        )
        if not named:
            missing.append(rel)
    assert not missing, f"docs/README.md does not name: {missing}"
