"""The joint PD / FL / NMPC report runs end to end (smoke mode) and says what it found."""

from __future__ import annotations

import csv
import json
import runpy
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_joint_report_compares_three_controllers_with_robustness(tmp_path):
    mod = runpy.run_path(str(ROOT / "designs" / "nonlinear_comparison.py"), run_name="design")
    rc = mod["main"](["--quick", "--no-jit", "--workers", "2", "--out", str(tmp_path)])
    html = (tmp_path / "report.html").read_text()
    assert (tmp_path / "report.pdf").read_bytes().startswith(b"%PDF")
    for heading in ("Validation and comparison", "Robustness", "Paper 002 bounds, full plant",
                    "Controllers", "Provenance"):
        assert heading in html
    for quantity in ("IAE", "air drawn from the supply", "command activity",
                     "worst settling time", "worst overshoot", "worst steady-state error"):
        assert quantity in html
    s = json.loads((tmp_path / "summary.json").read_text())
    assert rc == (0 if s["design_passed"] else 1)
    assert set(s["figures"]["full"]) == {"PD", "FL", "NMPC"}
    for key in ("default_full", "default_nominal", "paper002_full"):
        r = s["robustness"][key]
        assert r["seed"] == 2026 and len(r["draws"]) == 2
        assert set(r["controllers"]) == {"PD", "FL", "NMPC"}
        rows = list(csv.DictReader((tmp_path / f"robustness_{key}.csv").open()))
        assert len(rows) == 2
        # the CSV says the same as the JSON, draw by draw
        for i, row in enumerate(rows):
            for name in ("PD", "FL", "NMPC"):
                assert bool(int(row[f"{name}_passed"])) == r["controllers"][name]["passed"][i]
    # the same seed draws the same plants for every set with the same ranges
    assert s["robustness"]["default_full"]["draws"] == s["robustness"]["default_nominal"]["draws"]
