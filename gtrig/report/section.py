"""One section of the report's page (an anchor, a title, HTML parts) and the small readers the sections share.

Figures are embedded as PNG drawn at the page's width (``FIG_WIDTH_IN`` inches at ``FIG_DPI``, about 1300 px:
the content width of a 1400 px window), so the browser shows them at their own size, never magnified."""

from __future__ import annotations

import base64
import csv
import html
import io
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: the width every figure is drawn at (inches) and its resolution: 13 in x 100 dpi = 1300 px
FIG_WIDTH_IN = 13.0
FIG_DPI = 100


#: the height a figure drawn for a file is stretched to at most when widened (inches), unless drawn taller
MAX_STRETCHED_HEIGHT_IN = 6.5


def fit_to_page(fig: Any) -> None:
    """Widen ``fig`` to the page's width; its height grows in proportion up to ``MAX_STRETCHED_HEIGHT_IN``
    (or its own height, when drawn taller). Fonts keep their point size, so a figure drawn small for a file
    gets room rather than larger letters, and a square one does not fill the screen."""
    w, h = fig.get_size_inches()
    if w > 0 and abs(w - FIG_WIDTH_IN) > 1e-6:
        fig.set_size_inches(FIG_WIDTH_IN, min(h * FIG_WIDTH_IN / w, max(h, MAX_STRETCHED_HEIGHT_IN)))


#: a cell shown right-aligned: numbers (one, or several joined by ", ", " / ", " .. "), with "%" or "of N"
#: after them, or a dash (markup stripped first)
_NUM = r"[-+]?(?:\d[\d.]*(?:e[-+]?\d+)?|nan|inf)"
_NUMERIC = re.compile(rf"{_NUM}(?:(?:, | / | \.\. ){_NUM})*(?: ?%| of \d+)?|-", re.IGNORECASE)
_TAG = re.compile(r"<[^>]+>")


def td(cell: str) -> str:
    """A ``<td>`` of already escaped HTML: numbers right-aligned (class ``n``), text left-aligned."""
    return f'<td class="n">{cell}</td>' if _NUMERIC.fullmatch(_TAG.sub("", cell).strip()) else f"<td>{cell}</td>"


def table_html(header: list[str], rows: list[list[str]]) -> str:
    """A table of already escaped cells."""
    return ("<table><thead><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr></thead><tbody>"
            + "".join("<tr>" + "".join(td(c) for c in r) + "</tr>" for r in rows) + "</tbody></table>")


@dataclass
class Section:
    """One section of the page: an anchor ``key``, a ``title`` and HTML ``parts``."""

    key: str
    title: str
    parts: list[str] = field(default_factory=list)
    n_figures: int = 0

    def add(self, fragment: str) -> None:
        self.parts.append(fragment)

    def figure(self, fig: Any, caption: str) -> None:
        """Embed ``fig`` (closed afterwards) as a PNG at the page's width, with ``caption`` below it."""
        import matplotlib.pyplot as plt

        fit_to_page(fig)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=FIG_DPI)
        plt.close(fig)
        data = base64.b64encode(buf.getvalue()).decode("ascii")
        self.parts.append(f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
                          f"<figcaption>{html.escape(caption)}</figcaption></figure>")
        self.n_figures += 1

    def table(self, header: list[str], rows: list[list[str]], raw: bool = False) -> None:
        """A table; cells are escaped unless ``raw`` (the caller escaped them and added its own markup)."""
        self.parts.append(table_html(header, rows if raw else [[html.escape(c) for c in r] for r in rows]))

    def warnings(self, lines: list[str]) -> None:
        """A list of warnings, one item each."""
        if lines:
            self.parts.append('<ul class="warn">' + "".join(f"<li>{html.escape(x)}</li>" for x in lines)
                              + "</ul>")

    def html(self) -> str:
        return f'<section id="{self.key}"><h2>{html.escape(self.title)}</h2>' + "\n".join(self.parts) + "</section>"


def read_csv(p: Path) -> list[dict[str, str]]:
    """The rows of a CSV with a header (``#`` comment lines skipped)."""
    with open(p, encoding="utf-8", newline="") as f:
        return list(csv.DictReader(row for row in f if not row.startswith("#")))
