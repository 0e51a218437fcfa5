"""Exceptions with messages a rig engineer can act on."""

from __future__ import annotations

__all__ = ["WorkbenchError", "InputError"]


class WorkbenchError(Exception):
    """Base class of every error the workbench raises on purpose."""


class InputError(WorkbenchError, ValueError):
    """A file or argument given by the user is not what was expected.

    The message always names the source (file, line, column or key) and what was
    expected, so the user can fix the input without reading the code.
    """

    def __init__(self, message: str, *, source: str | None = None,
                 location: str | None = None) -> None:
        self.source = source
        self.location = location
        prefix = ""
        if source:
            prefix = f"{source}"
            if location:
                prefix += f", {location}"
            prefix += ": "
        super().__init__(prefix + message)
