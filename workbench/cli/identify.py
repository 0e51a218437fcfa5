"""``workbench identify METHOD``: arx, rls, valve, valve-table, greybox.

Temporary: registers the ``add_cli`` of each identification module as today (the
identify re-layout replaces this module with its own ``register``).
"""

from __future__ import annotations

import importlib

from .common import EPILOG

__all__ = ["register"]

#: Modules of :mod:`workbench.identify` that add a ``workbench identify`` sub-command.
IDENTIFY_MODULES = ("arx", "rls", "valve_fit", "grey_box")


def register(subparsers) -> None:
    """Add ``identify`` and its methods to ``workbench``'s sub-parsers."""
    ident = subparsers.add_parser("identify", help="models from recordings: arx, rls, valve, "
                                                   "greybox",
                                  description="Identification from recorded data. Each method "
                                              "has its own sub-command; --help on each.",
                                  epilog=EPILOG)
    isub = ident.add_subparsers(dest="method", metavar="METHOD")
    isub.required = True
    for mod in IDENTIFY_MODULES:
        importlib.import_module(f"workbench.identify.{mod}").add_cli(isub)
