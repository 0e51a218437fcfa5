"""``workbench bench NAME``: run a benchmark of :mod:`workbench.bench` and print its result."""

from __future__ import annotations

import argparse
import json

from .common import EPILOG

__all__ = ["register"]

DESCRIPTION = ("Benchmarks measure ours and the strongest plain baselines in the same run "
               "(median and spread of wall and CPU time, accuracy reached, ratios). NAME: "
               "simulate (closed loop 24 s, 4 states and 22 states with lines, vs CVODES in a "
               "mapaccum and a compiled RK4 at the same accuracy); sweep (200 x 200 stability "
               "map vs a batched numpy/CasADi version); rls (RLS over 10^6 samples vs a numba "
               "loop); greybox (4 parameters from a 20 s, 1 kHz recording vs scipy least_squares "
               "on CVODES replays); mpc (NMPC per "
               "sample over a 10 s closed loop vs a plain CasADi RTI with OSQP, IPOPT and "
               "do-mpc); diagnose (24 s, 1 kHz recording: one effect, and every set of up to "
               "two effects).")


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
