"""``workbench bench diagnose`` reports CPU seconds that include the worker processes.

The candidate refits run in worker processes, so the CPU time of a diagnosis is mostly
theirs; on a loaded machine it is the steadier figure than wall time. Checked against
a child process that burns a known amount of CPU (measured by itself, independently).
"""

from __future__ import annotations

import subprocess
import sys

from workbench.bench.diagnose import _cpu

BURN = ("import time\n"
        "t0 = time.process_time()\n"
        "while time.process_time() - t0 < 0.4:\n"
        "    pass\n"
        "print(time.process_time() - t0)\n")


def test_cpu_seconds_include_finished_child_processes():
    """A child that burns 0.4 s of CPU (by its own clock) raises _cpu() by at least
    that (plus the interpreter's start-up, so no upper bound that load could break
    other than a generous 5 s)."""
    before = _cpu()
    out = subprocess.run([sys.executable, "-c", BURN], capture_output=True, text=True,
                         check=True)
    burned = float(out.stdout)
    grown = _cpu() - before
    assert burned >= 0.4
    assert burned - 0.02 <= grown < burned + 5.0
