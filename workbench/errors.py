"""Exceptions with messages a rig engineer can act on."""

from __future__ import annotations

__all__ = ["WorkbenchError", "InputError", "InputWarning"]


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


def positive(name: str, value, unit: str) -> float:
    """``value`` as a finite float > 0, else an :class:`InputError` naming it and its unit."""
    import math
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number in {unit}, got {value!r}") from None
    if not math.isfinite(v) or v <= 0.0:
        raise InputError(f"{name} must be a finite number > 0 {unit}, got {value!r}")
    return v


class InputWarning(UserWarning):
    """An input was read, but part of it was left out or read in a way the user should
    know about (an unused column that holds text). The command line prints it as one
    line ``workbench COMMAND: warning: ...``; the message names the file and where."""
