"""Proof of the mismatch diagnosis on concealed data.

A rig (the 25 mm rig of ``designs/plants/rig25_mpye.toml`` with the PD loop kp = 5 V/m,
kd = 0.1 V s/m at 10 ms) gets one extra effect drawn at random (seeded) from formats.md
section 2 -- or none, or a wrong moving mass -- with its values drawn from realistic
ranges (:mod:`workbench.diagnose.synth`). The rig is run in closed loop on a rich
reference (steps both ways, ramps, holds, small steps) for 24 s and logged at 1 kHz
with sensor noise and 12-bit quantisation on x and the pressures. Each case is written
to ``cases/NN/`` as the nominal plant file and the recording CSV; the diagnosis is run
as a user would, on those two files only, in a separate process that never sees the
truth. The report shows the confusion table (named vs concealed effect), the fitted
values against the concealed ones and the fit gain.

Usage::

    python designs/diagnose_concealed.py            # 20 cases (each kind twice), ~10 min
    python designs/diagnose_concealed.py --quick    # 3 short cases (smoke test)
    python designs/diagnose_concealed.py --cases 10 --seed 7 --out reports/x

Writes ``reports/diagnose_concealed/report.html`` and ``report.pdf``, ``summary.json``
and ``cases/NN/{plant.toml, recording.csv, diagnosis/...}``. The verdict (quick mode
too) is PASS when every case is named correctly and every checked value is within 30 %;
the exit code is 0 then, else 1.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from workbench import report as rp  # noqa: E402
from workbench.diagnose import synth  # noqa: E402
from workbench.params import atomic_write_text  # noqa: E402

TITLE = "Mismatch diagnosis on concealed data"
OUT = ROOT / "reports" / "diagnose_concealed"


def draw_cases(n: int, seed: int) -> list[tuple[str, int]]:
    """(concealed kind, seed) pairs: every kind once per round, in a seeded random order."""
    rng = np.random.default_rng(seed)
    kinds: list[str] = []
    while len(kinds) < n:
        kinds += list(rng.permutation(synth.CONCEALED))
    return [(str(k), int(seed * 1000 + i)) for i, k in enumerate(kinds[:n])]


def run_case(i: int, kind: str, seed: int, out: Path, duration: float) -> dict:
    from workbench.errors import WorkbenchError
    d = out / "cases" / f"{i:02d}"
    d.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    redrawn = []
    for attempt in range(4):
        case = synth.concealed_case(kind, seed=seed)
        try:
            rec = synth.record(case, seed=seed, duration=duration)
            break
        except WorkbenchError as exc:
            # the rig's own simulation failed (not the diagnosis): draw again
            redrawn.append(f"seed {seed}: {str(exc).splitlines()[0][:80]}")
            seed += 100_000
    else:
        return {"case": i, "concealed": kind, "seed": seed, "values": {},
                "error": "the rig could not be simulated: " + "; ".join(redrawn), "wall_s": 0.0}
    plant_file = case.write_nominal(d / "plant.toml")
    t_rec = time.perf_counter() - t0
    rec_file = rec.to_csv(d / "recording.csv")
    # the diagnosis runs blind, in its own process, on the two files only
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "workbench", "diagnose", str(plant_file),
                           str(rec_file), "--out", str(d / "diagnosis"), "--json"],
                          capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        return {"case": i, "concealed": kind, "seed": seed, "values": dict(case.values),
                "error": proc.stderr.strip().splitlines()[-1] if proc.stderr else "failed",
                "wall_s": wall}
    result = json.loads(proc.stdout)
    sc = synth.score(case, result)
    return {"case": i, "seed": seed, "values": dict(case.values), "result": result,
            "wall_s": wall, "record_s": t_rec, "redrawn": redrawn, **sc}


def build_report(rows: list[dict], quick: bool, wall: float) -> rp.Report:
    kinds = list(synth.CONCEALED)
    named_cols = [synth.EXPECTED_EFFECT[k] if k != "mass_error" else "parameter_error"
                  for k in kinds]
    cols = []
    for c in ["none"] + named_cols:
        if c not in cols:
            cols.append(c)
    conf = {k: {c: 0 for c in cols + ["error"]} for k in kinds}
    for r in rows:
        named = r.get("named", "error")
        conf[r["concealed"]][named if named in cols else "error"] += 1
    table = [[k] + [conf[k][c] for c in cols] + [conf[k]["error"]] for k in kinds
             if sum(conf[k].values())]
    ok = [r for r in rows if r.get("correct")]
    n = len(rows)
    checked = [r for r in rows if synth.CHECKED_KEYS.get(r["concealed"])]
    checked_ok = [r for r in checked if r.get("correct") and r.get("checked_ok")]
    improved = [r for r in rows if r.get("fit_gain") and r["concealed"] != "none"
                and all(v > 0 for v in r["fit_gain"].values())]
    n_eff = len([r for r in rows if r["concealed"] != "none"])
    verdict = len(ok) == n and len(checked_ok) == len(checked)
    status = rp.Status("PASS" if verdict else "FAIL",
                       f"{len(ok)}/{n} concealed effects named correctly; fitted value within "
                       f"30 % in {len(checked_ok)}/{len(checked)} checked cases; fit improved on "
                       f"every signal in {len(improved)}/{n_eff} cases with an effect")
    short = {k: k.replace("parameter_error", "param_error") for k in cols}
    conf_tab = rp.Table(["concealed \\ named"] + [short[c] for c in cols] + ["error"], table,
                        caption="Confusion table: concealed effect (rows) vs effect named first "
                                "by the diagnosis (columns); a wrong mass must be named "
                                "parameter_error (load.mass)")
    case_rows = []
    for r in rows:
        vals = ", ".join(f"{k.split('.', 1)[1]} = {rp.fmt(v, digits=3)}"
                         for k, v in r["values"].items())
        res = r.get("result", {})
        f0 = res.get("findings", [{}])
        par = ", ".join(f"{k} = {rp.fmt(v, digits=3)}" for k, v in
                        (f0[0].get("parameters", {}) if f0 else {}).items())
        err = ", ".join(f"{k.split('.', 1)[1]} {100 * e:+.0f} %"
                        for k, e in r.get("relative_errors", {}).items())
        fb, fa = res.get("fit_before", {}), res.get("fit_after", {})
        fits = " / ".join(f"{fb.get(s, float('nan')):.1f} -> {fa.get(s, float('nan')):.1f}"
                          for s in ("x", "p_a", "p_b") if s in fb)
        case_rows.append([r["case"], r["concealed"], vals or "-", r.get("named", "error"),
                          bool(r.get("correct")), par or "-", err or "-", fits,
                          round(float(r["wall_s"]), 1)])
    cases_tab = rp.Table(["#", "concealed", "concealed values", "named", "correct",
                          "fitted", "error", "fit x / p_a / p_b before -> after", "wall"],
                         case_rows, units=["", "", "SI", "", "", "SI", "", "%", "s"],
                         caption="Every case: concealed values, what the diagnosis named and "
                                 "fitted, and the fit before and after")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 4.2), constrained_layout=True)
    mat = np.array([[conf[k][c] for c in cols] for k in kinds])
    ax.imshow(mat, cmap="Greens")
    ax.set_xticks(range(len(cols)), [short[c] for c in cols], rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(kinds)), kinds, fontsize=8)
    for (a, b), v in np.ndenumerate(mat):
        if v:
            ax.text(b, a, str(v), ha="center", va="center", fontsize=9)
    ax.set_xlabel("named by the diagnosis")
    ax.set_ylabel("concealed")
    fig2, ax2 = plt.subplots(figsize=(8, 3.2), constrained_layout=True)
    for s, mk in (("x", "o"), ("p_a", "s"), ("p_b", "^")):
        ys = [r.get("fit_gain", {}).get(s, np.nan) for r in rows]
        ax2.plot(range(len(rows)), ys, mk, label=s)
    ax2.axhline(0, color="0.4", lw=0.8)
    ax2.set_xticks(range(len(rows)), [f"{r['case']}:{r['concealed']}" for r in rows],
                   rotation=60, ha="right", fontsize=7)
    ax2.set_ylabel("fit after - before [%-points]")
    ax2.legend(fontsize=8)
    ax2.grid(True, alpha=0.3)
    sections = [
        rp.Section("Summary", [
            rp.KeyValues([("cases", n), ("named correctly", len(ok)),
                          ("fitted value within 30 %", f"{len(checked_ok)}/{len(checked)}"),
                          ("mode", "quick (short recordings)" if quick else "full (24 s, 1 kHz)"),
                          ("median diagnosis wall time",
                           float(np.median([r["wall_s"] for r in rows])), "s"),
                          ("total wall time", wall, "s")]),
            rp.Paragraph("Each diagnosis ran in its own process on the nominal plant file and "
                         "the recording CSV only (workbench diagnose ... --json); the concealed "
                         "effect and its values were never passed to it."),
            conf_tab,
            rp.Figure(fig, caption="Confusion matrix", width=0.8)]),
        rp.Section("Cases", [cases_tab,
                             rp.Figure(fig2, caption="Fit gain per case and signal")]),
    ]
    return rp.Report(TITLE, subtitle="25 mm rig, PD loop kp = 5 V/m, kd = 0.1 V s/m at 10 ms; "
                                     "24 s at 1 kHz, 12-bit sensors",
                     status=status, sections=sections,
                     provenance=rp.provenance(plant_file=synth.RIG_FILE,
                                              command_line=" ".join(sys.argv)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 short cases (smoke test)")
    ap.add_argument("--cases", type=int, help="number of cases (default 20; quick 3)")
    ap.add_argument("--seed", type=int, default=2026, help="seed of the draws")
    ap.add_argument("--out", default=str(OUT), help="output folder")
    args = ap.parse_args(argv)
    out = Path(args.out)
    n = args.cases or (3 if args.quick else 2 * len(synth.CONCEALED))
    duration = 8.0 if args.quick else 24.0
    t0 = time.perf_counter()
    rows = []
    for i, (kind, seed) in enumerate(draw_cases(n, args.seed)):
        r = run_case(i, kind, seed, out, duration)
        rows.append(r)
        if r.get("redrawn"):
            print(f"case {i:2d}: the rig simulation failed and was drawn again: {r['redrawn']}")
        print(f"case {i:2d}: concealed {kind:<15} named {r.get('named', 'ERROR'):<16} "
              f"{'ok ' if r.get('correct') else 'WRONG'} {r['wall_s']:5.1f} s "
              f"{r.get('relative_errors', '')}", flush=True)
    wall = time.perf_counter() - t0
    doc = build_report(rows, args.quick, wall)
    passed = doc.status.outcome == "PASS"
    html, pdf = rp.write(doc, out)
    atomic_write_text(out / "summary.json", json.dumps(
        {"cases": [{k: v for k, v in r.items() if k != "result"} | {"result": r.get("result")}
                   for r in rows],
         "correct": sum(bool(r.get("correct")) for r in rows), "total": len(rows),
         "passed": passed, "quick": bool(args.quick), "wall_s": wall},
        indent=1, default=float) + "\n")
    print(f"{sum(bool(r.get('correct')) for r in rows)}/{len(rows)} named correctly; "
          f"verdict {doc.status.outcome}; report: {html}")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
