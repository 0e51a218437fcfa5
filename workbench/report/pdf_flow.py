"""Page flow of the PDF: figures and tables never leave a page half empty.

reportlab keeps a heading or caption with the next flowable by moving the whole
group to the next page when it does not fit; for a tall figure or a long table
that leaves most of a page blank. :class:`KeepGroup` replaces that rule:

* a **table** that does not fit is split by rows where the page ends (its
  heading, caption and header rows stay with the first rows; the header rows are
  repeated on the next page), never leaving fewer than :data:`MIN_ROWS` rows on
  either side;
* a **figure** that does not fit is scaled down to the space left when moving it
  would leave more than :data:`MAX_EMPTY` of the page empty (not below
  :data:`MIN_SCALE` of its size), and always when it needs to lose at most
  ``1 - EASY_SCALE`` of its size;
* a figure that still does not fit lets the text blocks that follow it (up to the
  next heading or figure) go first when they fit in the space left, and takes the
  top of the next page (:func:`float_figures`, called from the doc template).

So a page is left more than :data:`MAX_EMPTY` empty before a figure only when
the figure would have to shrink below :data:`MIN_SCALE` and no text after it
fits into the space left (a figure of nearly a page after half a page of text
at the end of a section).

The group always asks to be split (as reportlab's ``KeepTogether``), so every
heading inside it is handed to the doc template on its own and still reaches
the table of contents and the PDF outline.
"""

from __future__ import annotations

import io

from reportlab.platypus import Image
from reportlab.platypus.doctemplate import FrameBreak
from reportlab.platypus.flowables import Flowable, _listWrapOn

__all__ = ["KeepGroup", "float_figures", "MAX_EMPTY", "MIN_SCALE", "EASY_SCALE", "MAX_CARRY",
           "MOVE_EMPTY"]

#: Largest fraction of a page's text frame left empty before a figure or table
#: that moves to the next page.
MAX_EMPTY = 0.4

#: Smallest scale a figure is shrunk to so that it fits the rest of a page (at
#: half size a full-width plot's labels and legends are no longer readable).
MIN_SCALE = 0.6

#: A figure that fits at this scale or more is always shrunk rather than moved.
EASY_SCALE = 0.85

#: Fewest table rows left at the foot of a page or carried to the next one.
MIN_ROWS = 2

#: A split that would carry less than this fraction of a table's rows to the next
#: page moves the table whole instead, if that leaves at most :data:`MOVE_EMPTY` of
#: this page empty.
MAX_CARRY = 0.25

#: Largest fraction of a page left empty by moving a table whole to avoid an orphan
#: tail (below :data:`MAX_EMPTY`: the page's ink ends a few pt above the frame space
#: used, and a page measured at 59 % must not come of it).
MOVE_EMPTY = 0.35

_FUZZ = 1.0  # pt of slack when fitting scaled figures (rounding in reportlab's frame)


class KeepGroup(Flowable):
    """Lead flowables (headings, caption), a body (table or image), tail flowables.

    Parameters
    ----------
    lead : list of Flowable
        Kept on the same page as the start of the body (headings, a table caption).
    body : Flowable
        An ``Image`` (a figure: may be scaled) or a ``Table`` (may be split by rows).
    tail : list of Flowable
        After the body (a figure caption, a spacer).
    frame_height : float
        Height of a page's text frame, pt (what :data:`MAX_EMPTY` is a fraction of).
    png : bytes, optional
        The figure's PNG, to draw it again at a smaller size.
    """

    def __init__(self, lead, body, tail, frame_height, png=None):
        super().__init__()
        self.lead, self.body, self.tail = list(lead), body, list(tail)
        self.frame_height = float(frame_height)
        self.png = png

    @property
    def is_figure(self) -> bool:
        return self.png is not None

    def with_lead(self, more: list) -> "KeepGroup":
        """The same group with ``more`` flowables put in front of its lead."""
        return KeepGroup(list(more) + self.lead, self.body, self.tail, self.frame_height,
                         self.png)

    def content(self) -> list:
        return self.lead + [self.body] + self.tail

    def _height(self, flowables, aw) -> float:
        """Height of ``flowables`` stacked in a frame (not at its top), pt."""
        if not flowables:
            return 0.0
        return _listWrapOn(flowables, aw, self.canv)[1] + flowables[0].getSpaceBefore()

    def natural_height(self, aw: float) -> float:
        return self._height(self.content(), aw)

    def wrap(self, aw, ah):
        self._natural = self.natural_height(aw)
        return aw, 0xFFFFFF  # always split: the parts reach the doc template one by one

    def figure_scale(self, aw: float, ah: float) -> float:
        """Scale at which the figure (with lead and tail) fits ``ah``, <= 1."""
        img_h = self.body.drawHeight
        rest = self.natural_height(aw) - img_h
        return min(max((ah - rest - _FUZZ) / img_h, 0.0), 1.0)

    def fits_somehow(self, aw: float, ah: float) -> bool:
        """Fits as is, or scaled down within the rules of this module."""
        if self.natural_height(aw) <= ah:
            return True
        if not self.is_figure:
            return False
        s = self.figure_scale(aw, ah)
        return s >= EASY_SCALE or (s >= MIN_SCALE and ah > MAX_EMPTY * self.frame_height)

    def split(self, aw, ah):
        at_top = bool(getattr(getattr(self, "_frame", None), "_atTop", False))
        if self.natural_height(aw) <= ah:
            return self.content()
        if self.is_figure:
            if self.fits_somehow(aw, ah):
                s = self.figure_scale(aw, ah)
                img = Image(io.BytesIO(self.png), width=self.body.drawWidth * s,
                            height=self.body.drawHeight * s)
                img.hAlign = self.body.hAlign
                return self.lead + [img] + self.tail
            return ([] if at_top else [FrameBreak()]) + self.content()
        parts = self._split_rows(aw, ah)
        if parts and not at_top and self._orphan_tail(parts, aw, ah):
            return [FrameBreak()] + self.content()
        if not parts and at_top:  # a page is not enough: split anywhere, as reportlab does
            room = ah - self._height(self.lead, aw) - self.body.getSpaceBefore()
            parts = list(self.body.split(aw, room)) if room > 0 else []
        if len(parts) == 1:        # the table fits but for the tail (a spacer): drop it
            return self.lead + parts   # here, or it would open a page of its own
        if parts:
            return self.lead + parts + self.tail
        return ([] if at_top else [FrameBreak()]) + self.content()

    def _header_rows(self) -> int:
        """Rows the table repeats on every page (its header)."""
        head = getattr(self.body, "repeatRows", 0) or 0
        return head if isinstance(head, int) else len(head)

    def _orphan_tail(self, parts: list, aw: float, ah: float) -> bool:
        """True when a split would carry only a few rows (fewer than :data:`MAX_CARRY`
        of the table) to the next page while the whole table fits there and moving it
        leaves this page at most :data:`MOVE_EMPTY` empty: a report's last page holding
        two rows of its provenance reads worse than the table kept together."""
        tables = [p for p in parts if hasattr(p, "_cellvalues")]
        if len(tables) < 2:
            return False
        head = self._header_rows()
        carried = sum(len(t._cellvalues) - head for t in tables[1:])
        rows = len(self.body._cellvalues) - head
        return (carried < MAX_CARRY * rows and ah <= MOVE_EMPTY * self.frame_height
                and self.natural_height(aw) <= self.frame_height)

    def _split_rows(self, aw: float, ah: float) -> list:
        """The table split where the page ends, at least :data:`MIN_ROWS` rows each side."""
        room = ah - self._height(self.lead, aw) - self.body.getSpaceBefore()
        head = self._header_rows()
        for _ in range(3 + MIN_ROWS):  # spacing and widows: shrink the room until right
            parts = self.body.split(aw, room) if room > 0 else []
            if len(parts) == 1:    # reportlab sees the table whole within room:
                over = self._height(self.lead + parts, aw) - ah
                if over <= 0:      # it fits; only the tail (a spacer) goes over
                    return parts
                room -= over + _FUZZ   # the heading's spacing it left out: take less
                continue
            if len(parts) < 2:
                return []
            first = len(parts[0]._cellvalues) - head
            last = sum(len(p._cellvalues) - head for p in parts[1:])
            if first < MIN_ROWS:
                return []
            excess = self._height(self.lead + [parts[0]], aw) - ah
            if excess <= 0 and last >= MIN_ROWS:  # the rest starts the next page
                return [parts[0], FrameBreak()] + list(parts[1:])
            if excess > 0:         # reportlab's estimate was too generous: take less
                room -= excess + _FUZZ
            else:                  # it fits but carries too few rows: end the first part one
                room += excess - parts[0]._rowHeights[-1] - _FUZZ   # row earlier than it did
        return []


def _movable(f) -> bool:
    """A block that may go before a figure that waits for the next page."""
    if isinstance(f, KeepGroup):
        return not f.is_figure and not any(getattr(x, "_wb_toc", None) for x in f.lead)
    if getattr(f, "_wb_toc", None) is not None:        # a heading
        return False
    return not getattr(f, "getKeepWithNext", lambda: False)()


def float_figures(flowables: list, frame, canv, frame_height: float) -> None:
    """Let text go before a figure that fits nowhere on this page (in place).

    Called by the doc template before it handles ``flowables[0]``. When that is a
    figure group that neither fits nor may be shrunk into the rest of the page,
    and the page would otherwise be left more than :data:`MAX_EMPTY` empty, the
    next block is moved before the figure if it fits entirely into the space
    left (its headings first, when the figure's group holds them); repeated for
    each following block up to the next heading or figure.
    """
    if not flowables or not isinstance(flowables[0], KeepGroup):
        return
    group = flowables[0]
    if not group.is_figure or getattr(frame, "_atTop", False):
        return
    aw = frame._getAvailableWidth()
    ah = frame._y - frame._y1p
    if ah <= MAX_EMPTY * frame_height:
        return
    group.canv = canv
    if group.fits_somehow(aw, ah):
        return
    if len(flowables) < 2 or not _movable(flowables[1]):
        return
    nxt = flowables[1]
    nxt.canv = canv
    heads = [f for f in group.lead if getattr(f, "_wb_toc", None) is not None
             or getattr(f, "getKeepWithNext", lambda: False)()]
    try:
        need = _listWrapOn(heads + [nxt], aw, canv)[1]
    except Exception:  # noqa: BLE001 - a block that cannot be measured stays where it is
        return
    if need > ah:
        return
    rest = KeepGroup([f for f in group.lead if f not in heads], group.body, group.tail,
                     group.frame_height, group.png)
    flowables[0:2] = heads + [nxt, rest]
