"""Write a report as HTML and PDF, atomically: the old files or the new, never half."""

from __future__ import annotations

import dataclasses
import os
import tempfile
import traceback
from pathlib import Path
from typing import Sequence

from ..params import usual_permissions
from .document import Paragraph, Preformatted, Report, ReportError, Section, Status
from .html import render_html
from .pdf import render_pdf

__all__ = ["write", "write_failure"]


def write(report: Report, out_dir: str | os.PathLike, stem: str = "report") -> tuple[Path, Path]:
    """Write ``out_dir/<stem>.html`` and ``out_dir/<stem>.pdf`` with the same content.

    Both files are rendered completely in memory, written to temporary files in
    ``out_dir`` and only then moved over the old ones with :func:`os.replace`. If
    anything fails, the temporary files are removed, the previous report (if any)
    is left as it was, and the error is raised. (Between the two renames a reader
    could see the new HTML next to the old PDF for an instant; each file on its
    own is always complete.)

    Parameters
    ----------
    report : Report
        The document.
    out_dir : path-like
        Output folder, created if missing.
    stem : str
        File name without extension.

    Returns
    -------
    (pathlib.Path, pathlib.Path)
        Paths of the HTML and the PDF file.

    Raises
    ------
    ReportError
        A block cannot be rendered (the message names the section and block) or
        the files cannot be written.

    Examples
    --------
    >>> from workbench import report as rp
    >>> doc = rp.Report("PD loop", status=rp.Status("PASS", "all limits met"),
    ...                 sections=[rp.Section("Limits", [rp.Table(["gain", "K0"], [["PCT", 12.5]],
    ...                                      units=["", "1/s"], caption="gain limits")])])
    >>> import tempfile
    >>> tmp_dir = tempfile.mkdtemp()
    >>> html_path, pdf_path = rp.write(doc, tmp_dir)
    >>> html_path.name, pdf_path.read_bytes()[:4]
    ('report.html', b'%PDF')
    """
    if not isinstance(report, Report):
        raise ReportError(f"write: expected a Report, got {type(report).__name__}")
    if not stem or os.sep in stem or (os.altsep and os.altsep in stem) or stem in (".", ".."):
        raise ReportError(f"write: stem must be a plain file name without folders, got {stem!r}")
    out = Path(out_dir)
    if report.date is None:  # one date for both files, even without provenance
        report = dataclasses.replace(report, date=report.shown_date())
    # Render everything first: a failure here touches no file at all.
    try:
        html = render_html(report).encode("utf-8")
    except ReportError:
        raise
    except Exception as exc:
        raise ReportError(f"HTML could not be rendered: {type(exc).__name__}: {exc}") from exc
    try:
        pdf = render_pdf(report)
    except ReportError:
        raise
    except Exception as exc:
        raise ReportError(f"PDF could not be rendered: {type(exc).__name__}: {exc}") from exc
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ReportError(f"cannot create the report folder {str(out)!r}: "
                          f"{exc.strerror or exc}") from exc
    targets = [(out / f"{stem}.html", html), (out / f"{stem}.pdf", pdf)]
    temps: list[str] = []
    try:
        for target, data in targets:
            fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=out)
            temps.append(tmp)
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        for (target, _), tmp in zip(targets, temps):
            usual_permissions(tmp, target)
            os.replace(tmp, target)
    except OSError as exc:
        raise ReportError(f"cannot write the report into {str(out)!r}: "
                          f"{exc.strerror or exc}") from exc
    finally:
        for tmp in temps:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass
    return targets[0][0], targets[1][0]


def write_failure(out_dir: str | os.PathLike, title: str, error: BaseException | str,
                  step: str | None = None, partial_sections: Sequence[Section] = (),
                  subtitle: str | None = None, provenance: Sequence[tuple[str, object]] = (),
                  stem: str = "report") -> tuple[Path, Path]:
    """Write a report for a design that failed or crashed: an ERROR banner saying what failed.

    The banner reads ``design failed at step '<step>': <ExceptionType>: <message>``;
    a "Failure" section repeats it with the traceback. The sections that were
    finished before the failure follow. If those cannot be rendered either, they
    are dropped (a note says so) so that a failure report is always written.

    Parameters
    ----------
    out_dir : path-like
        Output folder.
    title : str
        Report title (the design's title).
    error : exception or str
        What went wrong.
    step : str, optional
        The design step that failed (``"gain limits"``).
    partial_sections : sequence of Section
        Results finished before the failure.
    subtitle : str, optional
        As in :class:`Report`.
    provenance : sequence of (label, value)
        As in :class:`Report`.
    stem : str
        File name without extension.

    Returns
    -------
    (pathlib.Path, pathlib.Path)
        Paths of the HTML and the PDF file.
    """
    if isinstance(error, BaseException):
        what = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
        tb = "".join(traceback.format_exception(type(error), error, error.__traceback__))
    else:
        what, tb = str(error), ""
    where = f" at step {step!r}" if step else ""
    message = f"design failed{where}: {what}"
    failure = [Paragraph(f"The design did not finish{where}. The error was:"),
               Preformatted(what)]
    if tb and error.__traceback__ is not None:
        failure += [Paragraph("Traceback (most recent call last at the bottom):"),
                    Preformatted(tb.rstrip())]
    if partial_sections:
        failure.append(Paragraph("The sections below were finished before the failure; "
                                 "results after it are missing."))

    def make(sections, note=None):
        blocks = list(failure) + ([Status("NOTE", note)] if note else [])
        return Report(title, subtitle=subtitle, status=Status("ERROR", message),
                      sections=[Section("Failure", blocks), *sections], provenance=provenance)

    try:
        return write(make(partial_sections), out_dir, stem)
    except ReportError as exc:
        if not partial_sections:
            raise
        note = (f"The finished sections could not be rendered and were left out: {exc}")
        return write(make((), note), out_dir, stem)
