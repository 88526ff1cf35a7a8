"""The user guide holds together: README.md within its length, every relative link in README.md
and docs/ resolves, every file and ``python -m`` module the guide names exists (a file moved
without its documentation fails here), and every file in docs/ (figures, tables, results) is
named in docs/README.md with the command that wrote it or as a hand-written guide."""

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


# a path in the text, not a pattern (sitl-<flight>.json, campaign_roa*.yaml)
PATH_REF = re.compile(
    r"(?<![\w/.])((?:mpf_mavlink|sim|tests|configs|scripts|docs)/[\w./-]*\w)(?![\w*<{-])"
)
MODULE_REF = re.compile(r"python -m ([\w.]+)")


def test_the_files_and_modules_the_guide_names_exist():
    import importlib.util

    bad = []
    for md in _markdown():
        text = md.read_text()
        for ref in PATH_REF.findall(text):
            if not (ROOT / ref).exists() and not (ROOT / ref).with_suffix("").exists():
                bad.append(f"{md.relative_to(ROOT)}: {ref}")
        for mod in MODULE_REF.findall(text):
            mod = mod.rstrip(".")
            if (
                mod.split(".")[0] in ("mpf_mavlink", "sim")
                and importlib.util.find_spec(mod) is None
            ):
                bad.append(f"{md.relative_to(ROOT)}: python -m {mod}")
    assert not bad, "the guide names what does not exist: " + "; ".join(sorted(set(bad)))
