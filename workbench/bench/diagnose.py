"""``workbench bench diagnose``: wall time of a whole diagnosis, all candidates.

A 24 s, 1 kHz closed-loop recording of the 25 mm rig (PD loop) with a concealed
effect (dry friction) is made once (not timed); then the diagnosis runs on it with every
candidate. Target: under 60 s on two cores. The compiled replays are cached on disk
(``$WORKBENCH_CACHE``), so the first run on a machine also pays the C compilation; it
is reported separately (``first_run_s``) when the cache was cold.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

__all__ = ["bench"]


def bench(quick: bool = False) -> dict:
    """Diagnose a 24 s (quick: 8 s) recording with all candidates; return timings (s)."""
    from ..diagnose import diagnose, synth
    duration = 8.0 if quick else 24.0
    effect = "dry_friction"
    case = synth.concealed_case(effect, seed=11)
    t0 = time.perf_counter()
    rec = synth.record(case, seed=11, duration=duration)
    t_rec = time.perf_counter() - t0
    with tempfile.TemporaryDirectory(prefix="wb_bench_diag_") as tmp:
        plant_file = case.write_nominal(Path(tmp) / "plant.toml")
        rec_file = rec.to_csv(Path(tmp) / "recording.csv")
        t0 = time.perf_counter()
        d = diagnose(plant_file, rec_file)
        wall = time.perf_counter() - t0
        t0 = time.perf_counter()
        d.write(Path(tmp) / "out")
        t_write = time.perf_counter() - t0
    named = d.findings[0].effect if d.findings else "none"
    return {
        "wall_s": round(wall, 2),
        "target_s": 60.0,
        "recording_s": duration,
        "samples": len(rec),
        "candidates": len(d.ranking),
        "cores": os.cpu_count(),
        "stages_s": d.timings,
        "report_write_s": round(t_write, 2),
        "make_recording_s": round(t_rec, 2),
        "concealed": effect,
        "named": named,
        "correct": named == effect,
        "fit_before": d.fit_before,
        "fit_after": d.fit_after,
    }
