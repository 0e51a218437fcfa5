"""``python -m workbench``: the command line of :mod:`workbench.cli`."""

from .cli import build_parser, main

__all__ = ["main", "build_parser"]

if __name__ == "__main__":
    raise SystemExit(main())
