"""The user documentation (README.md, BENCHMARKS.md, docs/*.md) speaks of the software: no work-log
headings or wording, and every relative link points to a file of the repository."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = sorted([REPO / "README.md", REPO / "BENCHMARKS.md", *(REPO / "docs").glob("*.md")])


#: a heading (a line starting with '#') that names how the software was made rather than what it does
LOG_HEADING = re.compile(r"\bsessions?\b|\bissue\s*#?\d+|\(h\d+[a-z]?\)|\bh\d{1,2}[a-z]?\b|\bhelpers?\b|\blead\b",
                         re.IGNORECASE)

#: the same in running text: session names, issue numbers, branch tags, the team's roles
LOG_WORDS = re.compile(
    r"\bsession\s+\d+|\b(?:this|last|next|previous|that|each|one|every)\s+session\b|\bsessions\b"
    r"|\bissue\s*#?\d+|\(h\d+[a-z]?\)|\bbranch\s+h\d+|\bh\d{1,2}[a-z]?'s\b|\bhelper\b|\bthe lead\b|\blead's\b",
    re.IGNORECASE)

#: a date standing alone (a dated run), not a data set's name (Bovisa_2008-09-01, Bovisa 2008-09-01)
DATE = re.compile(r"(?<![\w-])(?<!Bovisa )(?<!Bicocca )20\d\d-\d\d-\d\d(?![\w-])")

#: a markdown link or image target: [text](target) / ![alt](target)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _name(page: Path) -> str:
    return page.relative_to(REPO).as_posix()


def _code_free_lines(text: str) -> list[tuple[int, str]]:
    """(line number, line) outside fenced code blocks."""
    out, fenced = [], False
    for no, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            out.append((no, line))
    return out


def _log_headings(page: Path) -> list[str]:
    return [f"{_name(page)}:{no}: {line}" for no, line in _code_free_lines(page.read_text(encoding="utf-8"))
            if line.startswith("#") and LOG_HEADING.search(line)]


def _work_log(page: Path) -> list[str]:
    """Every work-log heading, work-log wording and (outside BENCHMARKS.md) dated line of ``page``."""
    bad = _log_headings(page)
    for no, line in _code_free_lines(page.read_text(encoding="utf-8")):
        if LOG_WORDS.search(line):
            bad.append(f"{_name(page)}:{no}: {line.strip()[:100]}")
        if _name(page) != "BENCHMARKS.md" and DATE.search(line):  # the benchmark tables date their rows
            bad.append(f"{_name(page)}:{no}: dated: {line.strip()[:100]}")
    return bad


@pytest.mark.parametrize("page", PAGES, ids=_name)
def test_no_work_log_headings_or_wording(page: Path) -> None:
    bad = _work_log(page)
    assert not bad, "work-log wording (the history is in git log):\n" + "\n".join(bad)


def test_the_checks_catch_work_log_wording() -> None:
    """The patterns find what they are for, and leave ordinary words alone."""
    for heading in ("## Session 27 (h18)", "### Fixed in issue 19", "## Notes for the lead", "## h18f figures"):
        assert LOG_HEADING.search(heading), heading
    for words in ("as measured in session 34", "(issue 24)", "last session's thresholds", "branch h18",
                  "for the lead's rerun", "run on 2026-12-02"):
        assert LOG_WORDS.search(words) or DATE.search(words), words
    for fine in ("## Leading edge", "this leads to", "Bovisa_2008-09-01", "a misleading figure", "h = 0.35 m"):
        assert not (LOG_HEADING.search(fine) or LOG_WORDS.search(fine) or DATE.search(fine)), fine


@pytest.mark.parametrize("page", PAGES, ids=_name)
def test_relative_links_point_to_files(page: Path) -> None:
    missing = []
    for no, line in _code_free_lines(page.read_text(encoding="utf-8")):
        for target in LINK.findall(line):
            if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):  # a URL, an anchor
                continue
            path = (page.parent / target.split("#", 1)[0]).resolve()
            if not path.exists():
                missing.append(f"{_name(page)}:{no}: {target}")
    assert not missing, "links to files that do not exist:\n" + "\n".join(missing)
