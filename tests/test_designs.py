"""Design scripts run end to end in smoke mode (coarse map, short profile)."""

from __future__ import annotations

import json
import runpy
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def situm_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("situm_p_pd")
    mod = runpy.run_path(str(ROOT / "designs" / "situm_p_pd.py"), run_name="design")
    rc = mod["main"](["--quick", "--out", str(out)])
    return rc, out


def test_situm_design_writes_both_reports(situm_report):
    rc, out = situm_report
    html = (out / "report.html").read_text()
    pdf = (out / "report.pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and len(pdf) > 50_000          # figures embedded
    for heading in ("Linear model", "Gain limits", "Stability maps",
                    "Closed-loop validation on the nonlinear plant", "Table I ARX model vs PCT model",
                    "Provenance"):
        assert heading in html
    assert "http://" not in html.replace("http://www.w3.org", "")   # self-contained
    assert html.count("data:image/png;base64,") >= 5
    summary = json.loads((out / "summary.json").read_text())
    assert rc == (0 if summary["design_passed"] else 1)


def test_situm_design_reproduces_paper_000(situm_report):
    _, out = situm_report
    s = json.loads((out / "summary.json").read_text())
    lim = s["limits_table_ii"]
    # physics.md: 72.5 and 62.3 are quoted to 3 digits; "about 54" and "about 36"
    assert lim["continuous"] == pytest.approx(72.5, abs=0.05)
    assert lim["pct"] == pytest.approx(62.3, abs=0.05)
    assert lim["sampled"] == pytest.approx(54, abs=0.5)
    assert lim["sampled_delay"] == pytest.approx(36, abs=0.5)
    assert s["k0_p"] == pytest.approx(7.0, abs=0.05)                # Table II: K0 = 7.0
    # Table I ARX poles, physics.md: 0.861 +- 0.109j, 0.363 +- 0.019j (3 digits)
    key = lambda z: (round(z.real, 2), z.imag)                      # noqa: E731
    arx = sorted((complex(*p) for p in s["arx_poles"]), key=key)
    expected = sorted([0.861 + 0.109j, 0.861 - 0.109j, 0.363 + 0.019j, 0.363 - 0.019j], key=key)
    assert np.allclose(arx, expected, atol=1.5e-3)
    pct = [complex(*p) for p in s["pct_poles"]]
    assert any(abs(z - (0.928 + 0.076j)) < 1.5e-3 for z in pct)
    assert any(abs(z - 0.619) < 1.5e-3 for z in pct)
    # the map's |z| = 1 crossing at the rig's mass sits on the exact limit of the rig
    # model within one grid step of the quick map (90/39 = 2.3 1/s)
    assert abs(s["map_crossing_k0"] - s["limits_rig"]["sampled"]) < 2.4
    # the PD loop is faster than the paper's P loop and stable
    assert s["k0_pd"] > s["k0_p"] and s["rho_pd"] < 1


def test_failed_design_still_writes_a_report(tmp_path, monkeypatch):
    mod = runpy.run_path(str(ROOT / "designs" / "situm_p_pd.py"), run_name="design")
    main = mod["main"]
    g = main.__globals__

    def broken(*a, **k):
        raise RuntimeError("valve table missing")
    monkeypatch.setitem(g, "pd_design", broken)
    rc = main(["--quick", "--out", str(tmp_path)])
    assert rc == 1
    html = (tmp_path / "report.html").read_text()
    assert "valve table missing" in html and "controllers" in html
    assert (tmp_path / "report.pdf").read_bytes().startswith(b"%PDF")
