"""Docs, config comments and sources cite only files that are in the repository."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: What a reader of the repository reads: the README, docs, team files and the Python sources.
SCANNED = ("README.md", "docs/**/*.md", "configs/*.yaml", "flightkit/**/*.py", "gcs/**/*.py",
           "vehicle_emulator/**/*.py", "benchmarks/**/*.py")
#: A cited path starts with one of these folders (the repository's, and the two outside it that
#: documents have cited: spec/ and shared/), optionally behind ../ (which leaves the repository).
TOP = ("docs", "configs", "benchmarks", "tests", "flightkit", "gcs", "vehicle_emulator", "spec",
       "shared")
PATH = re.compile(r"(?<![\w./$<>{}-])((?:\.\./)*(?:" + "|".join(TOP) + r")/[\w./*<>{}-]*)")
#: A bare document name (`control-law.md`, not behind a folder): it must exist somewhere here.
DOC = re.compile(r"(?<![\w./-])([\w-]+\.md)\b")
#: Markdown files a command writes into its output directory (gcs/sweep/analysis.py), not
#: documents of the repository.
WRITTEN = {"summary.md", "report.md"}
#: Citations of the team's specification by section, which a reader of the repository lacks.
SPEC = re.compile(r"\bspec(?:'s)? (?:section|§|\d)|\bspec §|\bspec/")
PLACEHOLDER = re.compile(r"<[^>/]*>|\{[^}/]*\}")
UNCLOSED = re.compile(r"[{<][^}>]*$")


def scanned_files() -> list[Path]:
    return sorted({p for pattern in SCANNED for p in ROOT.glob(pattern) if p.is_file()})


def lines(path: Path) -> Iterator[tuple[int, str]]:
    yield from enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)


def cited_paths(text: str) -> list[str]:
    """The repository paths `text` cites, trailing punctuation and an unclosed `{`/`<` (an
    f-string's field after the name) removed."""
    return [UNCLOSED.sub("", m).rstrip(".") for m in PATH.findall(text)]


def resolves(cited: str) -> bool:
    """Whether a cited path names something in the repository (a placeholder `<name>`, `{x}`
    or a `*` must match at least one file)."""
    if cited.startswith("../"):
        return False  # outside the repository, whatever is there today
    pattern = PLACEHOLDER.sub("*", cited).rstrip("/")
    if "*" in pattern:
        return any(ROOT.glob(pattern))
    return (ROOT / pattern).exists()


@pytest.mark.parametrize(
    ("text", "cited", "ok"),
    [
        ("see docs/gcs.md, \"Records\".", ["docs/gcs.md"], True),
        ("(`configs/*.yaml`)", ["configs/*.yaml"], True),
        ("runs/<name>-fly, gcs/fly/command.py:", ["gcs/fly/command.py"], True),
        ("the schema (spec/flight-report.md)", ["spec/flight-report.md"], False),
        ("recorded in `../shared/data/sitl/`", ["../shared/data/sitl/"], False),
        ("docs/flight-report.md", ["docs/flight-report.md"], False),
        ("https://example.org/docs/x.md and foo/gcs/bar.py", [], True),
        ('f"benchmarks/bench_edges.py{" " + args}"', ["benchmarks/bench_edges.py"], True),
    ],
)
def test_the_scan_finds_cited_paths_and_judges_them(text, cited, ok):
    # GIVEN a line WHEN scanned THEN the paths it cites are found, and resolved or not
    assert cited_paths(text) == cited
    assert all(resolves(c) for c in cited_paths(text)) is ok


def test_every_cited_repository_path_exists():
    # GIVEN every document, team file and source a reader of the repository reads
    missing = [
        f"{path.relative_to(ROOT)}:{n}: {cited}"
        for path in scanned_files()
        for n, line in lines(path)
        for cited in cited_paths(line)
        if not resolves(cited)
    ]
    # THEN each path they cite is in the repository
    assert missing == [], "\n".join(missing)


def test_every_cited_document_name_exists():
    # GIVEN the names of the repository's documents
    docs = {p.name for p in ROOT.rglob("*.md") if ".venv" not in p.parts}
    # WHEN a line names a document without its folder THEN a document of that name exists
    missing = [
        f"{path.relative_to(ROOT)}:{n}: {name}"
        for path in scanned_files()
        for n, line in lines(path)
        for name in DOC.findall(line)
        if name not in docs and name not in WRITTEN
    ]
    assert missing == [], "\n".join(missing)


def test_nothing_cites_the_specification_by_section():
    # GIVEN the same files WHEN a line cites "spec section 9", "spec §6" or "spec 2.5"
    # THEN it points into docs/ instead (what a reader needs is there)
    found = [
        f"{path.relative_to(ROOT)}:{n}: {line.strip()}"
        for path in scanned_files()
        for n, line in lines(path)
        if SPEC.search(line)
    ]
    assert found == [], "\n".join(found)
