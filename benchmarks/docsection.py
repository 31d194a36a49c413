"""Replace (or append) one `## ` section of a Markdown file: how each benchmark writes its
figures into docs/benchmarks.md without touching the others' sections."""

from __future__ import annotations

from pathlib import Path


def write_section(doc_path: Path, heading: str, text: str) -> None:
    """`text` (starting with `heading`) in place of that section, else appended."""
    doc = doc_path.read_text() if doc_path.exists() else "# Benchmarks\n\n"
    start = doc.find(heading + "\n")
    if start < 0:
        doc = doc.rstrip("\n") + "\n\n" + text
    else:
        end = doc.find("\n## ", start + len(heading))
        rest = "" if end < 0 else "\n" + doc[end + 1:]  # a blank line before the next one
        doc = doc[:start] + text.rstrip("\n") + "\n" + rest
    doc_path.write_text(doc)


def publish(doc_path: Path, heading: str, text: str, write: bool = True) -> None:
    """Print a benchmark's section and, unless ``write`` is False (--no-write), put it in
    ``doc_path`` (write_section)."""
    print(text)
    if write:
        write_section(doc_path, heading, text)
