"""The self-contained HTML report of a pipeline output folder (``gtrig report RESULTS_DIR --out report.html``)."""

from gtrig.report.page import build_report, write_report

__all__ = ["build_report", "write_report"]
