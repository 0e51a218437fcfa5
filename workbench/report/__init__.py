"""Reports: one document, rendered as a self-contained HTML page and an A4 PDF.

Build a :class:`Report` from immutable blocks holding results computed elsewhere
(this package renders, it never computes), then :func:`write` it::

    from workbench import report as rp

    doc = rp.Report(
        "PD position loop, 15 mm rodless rig",
        status=rp.Status("PASS", "all limits met"),
        sections=[
            rp.Section("Plant", [rp.KeyValues([("bore", 15, "mm"), ("supply", 6.0, "bar")])]),
            rp.Section("Limits", [rp.Table(["limit", "K0"], [["PCT", 12.5]],
                                           units=["", "1/s"], caption="gain limits")]),
        ],
        provenance=rp.provenance(plant_file="designs/plants/situm_rodless.toml"),
    )
    html_path, pdf_path = rp.write(doc, "reports/situm_pd")

Layout rules every report gets (see :mod:`.columns` and :mod:`.pdf_flow`): one
number format per table column (numbers given as text included), one verdict
vocabulary (PASS / FAIL / NOTE / ERROR; "PASSED" is shown as PASS), no column
without a value, headers that never wrap inside a formula, and PDF pages that are
not left half empty before a figure or table that did not fit.

A design that fails still leaves a report saying what failed::

    except Exception as exc:
        rp.write_failure("reports/situm_pd", "PD position loop", exc, step="gain limits",
                         partial_sections=done)
"""

from .document import (OUTCOMES, Figure, Heading, KeyValues, Paragraph, Preformatted, Report,
                       ReportError, Section, Status, Table, fmt)
from .design import design_arguments, json_default, progress, run_design, say, step, write_summary
from .html import render_html
from .output import write, write_failure
from .pdf import render_pdf
from .provenance import file_sha256, git_revision, provenance

__all__ = [
    "run_design", "design_arguments", "step", "progress", "say", "json_default", "write_summary",
    "Report", "Section", "Heading", "Paragraph", "Preformatted", "KeyValues", "Table",
    "Figure", "Status", "OUTCOMES", "ReportError", "fmt", "provenance", "git_revision",
    "file_sha256", "render_html", "render_pdf", "write", "write_failure",
]
