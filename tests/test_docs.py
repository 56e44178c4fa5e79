"""The documentation speaks of the product: every citation of docs/design.md names one of its
sections, and the text users and readers meet (code, docs, problem files, benchmarks, examples,
README) tells no history of its making (issue numbers, work sessions, "stops", dates of work)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "docs" / "design.md"

#: The sections of docs/design.md, numbered as the code cites them.
SECTIONS = {
    1: "The problem",
    2: "Frames and conventions",
    3: "The light constraints h(q)",
    4: "Luminance model",
    5: "Landmarks",
    6: "From landmarks to a timed trajectory",
    7: "Robots, libraries and published limits",
    8: "Environment and collision",
    9: "The camera's view and the beam",
    10: "Light sets",
    11: "Camera in the loop",
    12: "Files and their frames (exports)",
    13: "Batch and cell design",
}

#: A citation: "docs/design.md" followed by one or more sections, "§2", "§2–§3", "§10, §12".
CITATION = re.compile(r"docs/design\.md((?:[ ,–-]+§\d+)+)")

#: What the product's text must not say: issue numbers, stops, sessions, dates of work.
HISTORY = re.compile(
    r"stop [0-9]|this stop|session|issue [0-9]|DESIGN §|measured this|before/after|until [0-9]+ (Nov|Dec)",
    re.IGNORECASE,
)

TEXT_SUFFIXES = {".py", ".md", ".toml", ".txt", ".cfg"}


def _text_files(*parts: str) -> list[Path]:
    files: list[Path] = []
    for part in parts:
        path = ROOT / part
        if path.is_file():
            files.append(path)
        elif path.is_dir():
            files += [
                p for p in sorted(path.rglob("*")) if p.is_file() and p.suffix in TEXT_SUFFIXES and "results" not in p.parts
            ]
    return files


def test_design_has_the_numbered_sections_in_order() -> None:
    headings = re.findall(r"^## §(\d+) (.+)$", DESIGN.read_text(), flags=re.MULTILINE)
    assert [(int(n), title) for n, title in headings] == list(SECTIONS.items())


@pytest.mark.parametrize("part", ["optlight", "tests", "benchmarks", "examples", "docs", "README.md"])
def test_every_design_citation_names_an_existing_section(part: str) -> None:
    cited: list[tuple[Path, int]] = []
    for path in _text_files(part):
        for match in CITATION.finditer(path.read_text(encoding="utf-8")):
            cited += [(path, int(n)) for n in re.findall(r"§(\d+)", match.group(1))]
    missing = [f"{p.relative_to(ROOT)}: §{n}" for p, n in cited if n not in SECTIONS]
    assert not missing, missing
    if part in ("optlight", "docs"):
        assert cited, f"no citation of docs/design.md found in {part}"


@pytest.mark.parametrize("part", ["optlight", "docs", "benchmarks", "examples", "README.md"])
def test_the_product_text_tells_no_history(part: str) -> None:
    found = []
    for path in _text_files(part):
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if HISTORY.search(line.replace('scope="session"', "")):
                found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "\n".join(found)
