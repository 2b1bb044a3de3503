"""The documentation stays true to the tree: docs/architecture.md names every module, the README is a front page,
every relative link resolves, and README.md and docs/ describe what the code is, not how it got there."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted((ROOT / "docs").glob("*.md"))
README_MAX_LINES = 250

# Markdown links and images: [text](target) and ![alt](target); the target up to a space or ")"
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
# process history: how the project got here rather than what it is
HISTORY = re.compile(
    r"\bsessions?\b|\bissues? #?\d+|\bpreviously\b|\bno longer\b|\bused to\b|\bat the start of this\b"
    r"|\(was\b|\bwas [^.;:()]{1,60}?,? now\b",
    flags=re.IGNORECASE,
)


def _modules() -> list[str]:
    """Every module of the package by its path from the repository root, __init__.py left out; factors/ once,
    not again through the symlink gtsam_dvl/factors -> ../factors."""
    out = []
    for top in ("gtsam_dvl", "factors"):
        for path in sorted((ROOT / top).rglob("*.py")):
            rel = path.relative_to(ROOT)
            if path.name == "__init__.py" or rel.parts[:2] == ("gtsam_dvl", "factors"):
                continue
            out.append(rel.as_posix())
    return out


def test_architecture_names_every_module() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text()
    modules = _modules()
    assert len(modules) > 50, modules  # the walk found the package
    missing = [m for m in modules if f"`{m}`" not in text]
    assert not missing, (
        "docs/architecture.md does not name these modules (add a row with their path): "
        + ", ".join(missing)
    )


def test_readme_is_a_front_page() -> None:
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= README_MAX_LINES, (
        f"README.md has {len(lines)} lines; move details to docs/"
    )


@pytest.mark.parametrize(
    "doc", [ROOT / "README.md", *DOCS], ids=lambda p: p.relative_to(ROOT).as_posix()
)
def test_relative_links_resolve(doc: Path) -> None:
    broken = []
    for target in LINK.findall(doc.read_text()):
        # URL, mail, in-page anchor
        if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
            continue
        path = target.split("#", 1)[0]
        if not (doc.parent / path).exists():
            broken.append(target)
    assert not broken, f"{doc.relative_to(ROOT)}: links to missing files: {broken}"


@pytest.mark.parametrize(
    "doc", [ROOT / "README.md", *DOCS], ids=lambda p: p.relative_to(ROOT).as_posix()
)
def test_no_process_history(doc: Path) -> None:
    hits = [
        f"{i}: {line.strip()}"
        for i, line in enumerate(doc.read_text().splitlines(), 1)
        if HISTORY.search(line)
    ]
    assert not hits, (
        f"{doc.relative_to(ROOT)} tells how the project got here, not what it is:\n"
        + "\n".join(hits)
    )


def test_history_pattern_catches_the_usual_phrases() -> None:
    for phrase in (
        "a session ago",
        "issue 12",
        "the previous session",
        "was 5 ms, now 20 ms",
        "(was 5 ms: ...)",
        "it is no longer needed",
        "previously computed",
    ):
        assert HISTORY.search(phrase), phrase
    for phrase in ("what was lost", "the issue of noise", "before the gap", "now and then"):
        assert not HISTORY.search(phrase), phrase
