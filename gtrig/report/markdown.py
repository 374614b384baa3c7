"""Stage summaries written as Markdown (headings, pipe tables, bullet and numbered lists, paragraphs) rendered
as HTML, escaped.

Only the subset gtrig's stages write; anything else is shown as a paragraph, never interpreted."""

from __future__ import annotations

import html
import re

from gtrig.report.section import table_html

#: a list item: ``- x``, ``* x``, ``+ x`` (bullets) or ``1. x`` / ``1) x`` (numbered); group 2 is the text
_ITEM = re.compile(r"^\s*([-*+]|\d+[.)])\s+(.*)$")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def markdown_to_html(text: str) -> str:
    """HTML of the Markdown ``text`` (headings shifted down two levels: the page has its own)."""
    out: list[str] = []
    lines = text.splitlines()
    i = 0
    para: list[str] = []
    items: list[str] = []
    ordered = False

    def flush() -> None:
        if para:
            out.append("<p>" + html.escape(" ".join(para)) + "</p>")
            para.clear()
        if items:
            tag = "ol" if ordered else "ul"
            out.append(f"<{tag}>" + "".join(f"<li>{html.escape(x)}</li>" for x in items) + f"</{tag}>")
            items.clear()

    while i < len(lines):
        s = lines[i].rstrip()
        if s.startswith("#"):
            flush()
            level = min(len(s) - len(s.lstrip("#")) + 2, 6)
            out.append(f"<h{level}>{html.escape(s.lstrip('#').strip())}</h{level}>")
        elif s.startswith("|") and i + 1 < len(lines) and set(lines[i + 1].replace("|", "").strip()) <= set("-: "):
            flush()
            head = _cells(s)
            rows = []
            i += 2
            while i < len(lines) and lines[i].strip().startswith("|"):
                rows.append(_cells(lines[i]))
                i += 1
            out.append(table_html(head, [[html.escape(c) for c in r] for r in rows]))
            continue
        elif (m := _ITEM.match(s)) is not None:
            if para or (items and ordered != m.group(1)[0].isdigit()):
                flush()
            ordered = m.group(1)[0].isdigit()
            items.append(m.group(2).strip())
        elif not s.strip():
            flush()
        elif items and s.startswith((" ", "\t")):  # a list item's continuation line
            items[-1] += " " + s.strip()
        else:
            if items:
                flush()
            para.append(s.strip())
        i += 1
    flush()
    return "\n".join(out)
