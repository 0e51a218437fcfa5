"""``workbench bench NAME``: run a benchmark of :mod:`workbench.bench` and print its result."""

from __future__ import annotations

import argparse
import json

from .common import EPILOG

__all__ = ["register"]

DESCRIPTION = ("Benchmarks measure against a baseline in the same run and print ratios. NAME: "
               "simulate (closed-loop 24 s, 25 mm reference plant, vs scipy solve_ivp LSODA); "
               "sweep (200 x 200 stability map vs a python-control loop); rls (RLS over 10^6 "
               "samples vs a numpy loop); greybox (4 parameters from a 20 s, 1 kHz recording); "
               "mpc (NMPC solve times over a 20 s closed loop, vs do-mpc when installed); "
               "diagnose (24 s, 1 kHz recording, all candidate effects).")


def register(subparsers) -> None:
    """Add ``bench`` to ``workbench``'s sub-parsers."""
    from ..bench import NAMES
    b = subparsers.add_parser("bench", help="run a benchmark and print ratios",
                              description=DESCRIPTION, epilog=EPILOG)
    b.add_argument("name", choices=NAMES, help="benchmark")
    b.add_argument("--json", action="store_true", help="print JSON")
    b.add_argument("--quick", action="store_true", help="shorter run (smoke test)")
    b.set_defaults(func=_bench)


def _bench(args: argparse.Namespace) -> int:
    from ..bench import run
    result = run(args.name, quick=args.quick)
    if args.json:
        from ..output import strict_json
        print(json.dumps(strict_json(result), indent=2))
    else:
        for k, v in result.items():
            print(f"{k}: {v}")
    return 0
