"""What every command module of :mod:`workbench.cli` shares."""

from __future__ import annotations

__all__ = ["EPILOG"]

#: Epilog of every command's ``--help``.
EPILOG = "Units are SI (m, Pa absolute, kg, s, V) unless an option says otherwise."
