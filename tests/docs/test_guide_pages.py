"""The guide pages state what is, not what happened.

The guide (``README.md`` and ``docs/*.md``) says what the code does now and its current
figures; the dated studies are the research log (``docs/notes/``) and the history is
``CHANGELOG.md``. So no guide page carries a date, a run number or an "until …" history (a
link to a dated note is fine: its file name is not a claim of the page), and the performance
page stays a page of targets and one current figure each (at most 250 lines), the README a
front door (at most 150).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
GUIDE = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
NOT_GUIDE = {"changelog.md"}  # the changelog's page includes CHANGELOG.md, which is dated

HISTORY = {
    "a date": re.compile(r"\b(19|20)\d\d-[01]\d-[0-3]\d\b"),
    'an "until <date>"': re.compile(r"(?i)\buntil (19|20)\d\d\b"),
    'a "since <date>"': re.compile(r"(?i)\bsince (19|20)\d\d\b"),
    # "the first run compiles the kernels" and "a second run is refused" say what is
    "a run number": re.compile(
        r"(?i)\b(third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|twelfth|"
        r"thirteenth|fourteenth|\d+(st|nd|rd|th)) run\b"
    ),
}
# Link targets and image paths may name a dated note or figure file.
LINK_TARGET = re.compile(
    r"\[[^\]]*\d{4}-\d\d-\d\d-[a-z0-9-]+\.md\]\([^)\s]*\)"  # [docs/notes/<date>-x.md](…)
    r"|\]\([^)\s]*\)"  # any link's target
    r"|`[^`]*\.(png|md|gif)`"  # a file named in code
)


def _history(text: str) -> list[str]:
    found = []
    for n, line in enumerate(text.splitlines(), 1):
        bare = LINK_TARGET.sub("", line)
        for what, pattern in HISTORY.items():
            if m := pattern.search(bare):
                found.append(f"{n}: {what}: {m.group(0)!r}")
    return found


@pytest.mark.parametrize(
    "page", [p for p in GUIDE if p.name not in NOT_GUIDE], ids=lambda p: p.name
)
def test_a_guide_page_carries_no_history(page: Path) -> None:
    found = _history(page.read_text(encoding="utf-8"))
    assert not found, (
        f"{page.relative_to(ROOT)} narrates history; move it to a dated note in docs/notes/ "
        "(and CHANGELOG.md), and state what is:\n" + "\n".join(found)
    )


@pytest.mark.parametrize(
    ("line", "bad"),
    [
        ("measured on 2026-11-27 on a znver4 host", True),
        ("the default until 2026-11-26", True),
        ("since 2026 it is", True),
        ("the fourteenth run of the evening", True),
        ("in the 3rd run", True),
        ("a second run is refused", False),
        ("[the study](notes/2026-11-27-float32-rays.md)", False),
        ("![curves](figures/dagger-general-mdn-2026-11-26.png)", False),
        ("`docs/notes/2026-11-24-general-student-recipes.md`", False),
        ("a run takes 3.5 min", False),
        ("until it reaches the goal", False),
    ],
)
def test_the_patterns_catch_what_they_should(line: str, bad: bool) -> None:
    assert bool(_history(line)) == bad


@pytest.mark.parametrize(
    ("page", "most", "fix"),
    [
        ("docs/performance.md", 250, "keep the targets and one current figure each"),
        ("README.md", 150, "keep it a front door: what it is, install, an example, links"),
    ],
)
def test_the_pages_that_must_stay_short(page: str, most: int, fix: str) -> None:
    lines = (ROOT / page).read_text(encoding="utf-8").splitlines()
    assert len(lines) <= most, (
        f"{page} has {len(lines)} lines (at most {most}): {fix}; move studies to docs/notes/"
    )


def test_the_research_log_is_dated() -> None:
    notes = [p for p in (ROOT / "docs" / "notes").glob("*.md") if p.name != "index.md"]
    assert notes
    undated = [p.name for p in notes if not re.match(r"\d{4}-\d\d-\d\d-[a-z0-9-]+\.md$", p.name)]
    assert not undated, f"a research note is named YYYY-MM-DD-topic.md: {undated}"
