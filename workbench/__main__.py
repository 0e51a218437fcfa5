"""``python -m workbench``: the command line of :mod:`workbench.cli`."""

import sys

try:
    from .cli import build_parser, main
except KeyboardInterrupt:               # Ctrl-C while Python was still starting
    if __name__ == "__main__":
        print("workbench: interrupted (Ctrl-C)", file=sys.stderr)
        raise SystemExit(130) from None
    raise

__all__ = ["main", "build_parser"]

if __name__ == "__main__":
    raise SystemExit(main())
