"""``workbench identify``: arx, rls, valve, valve-table, greybox.

One module per method (:mod:`.arx`, :mod:`.rls`, :mod:`.valve`, :mod:`.greybox`): each
sub-command parses its options, calls :mod:`workbench.identify` and prints or writes what
it returns; no estimation happens here. :func:`register` adds the group.
"""

from __future__ import annotations

from typing import Any

from .arx import add_arx
from .greybox import add_greybox
from .rls import add_rls
from .valve import add_valve

__all__ = ["register"]

EPILOG = "Units are SI (m, Pa absolute, kg, s, V) unless an option says otherwise."


def register(subparsers: Any) -> None:
    """Add the ``identify`` command group (arx, rls, valve, valve-table, greybox).

    Parameters
    ----------
    subparsers : argparse sub-parsers action of the ``workbench`` parser.
    """
    ident = subparsers.add_parser("identify",
                                  help="models from recordings: arx, rls, valve, greybox",
                                  description="Identification from recorded data. Each method "
                                              "has its own sub-command; --help on each.",
                                  epilog=EPILOG)
    isub = ident.add_subparsers(dest="method", metavar="METHOD")
    isub.required = True
    add_arx(isub)
    add_rls(isub)
    add_valve(isub)
    add_greybox(isub)
