"""Ctrl-C and SIGTERM (issue 15): stop at once, exit 130 / 143, write nothing, and an
interrupted run is never counted as a result.

CasADi polls for signals inside CVODES and reports a Ctrl-C as an ordinary failure
(``CVode returned "CV_RHSFUNC_FAIL"``); these tests send real signals to a real
``workbench`` process while it is inside CVODES and check what comes out.
"""

from __future__ import annotations

import os
from functools import partial
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from workbench import output
from workbench.errors import WorkbenchError

ROOT = Path(__file__).resolve().parents[1]
PLANT = ROOT / "designs" / "plants" / "rig25_mpye.toml"

linux_only = pytest.mark.skipif(not Path("/proc/self/maps").exists(),
                                reason="waits for CVODES via /proc/PID/maps")


@pytest.fixture(scope="module")
def long_recording(tmp_path_factory) -> Path:
    """120 s at 1 kHz of an open-loop command: ~16 s of CPU to replay, so a signal sent
    once CVODES runs lands inside the computation, and stopping within 8 s is "at once"
    even on a loaded machine."""
    t = np.arange(0.0, 120.0, 0.001)
    u = 5.0 + 0.3 * np.sin(2 * np.pi * 0.5 * t) + 0.2 * np.sign(np.sin(2 * np.pi * 3 * t))
    x = 0.25 + 0.01 * np.sin(2 * np.pi * 0.2 * t)
    path = tmp_path_factory.mktemp("rec") / "long.csv"
    path.write_text("t,u,x\n" + "\n".join(f"{a:.3f},{b:.4f},{c:.5f}"
                                          for a, b, c in zip(t, u, x)) + "\n")
    return path


def _start(args: list[str]) -> subprocess.Popen:
    """``python -m workbench ARGS`` in its own process group (as a terminal runs it)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen([sys.executable, "-m", "workbench", *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True,
                            # Ctrl-C's default in the child: a shell's background job starts
                            # with SIGINT ignored, and Python would keep ignoring it
                            preexec_fn=partial(signal.signal, signal.SIGINT, signal.SIG_DFL))


def _children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(c) for c in text.split()]


def _wait_inside_cvodes(proc: subprocess.Popen, timeout: float = 60.0) -> None:
    """Until the process (or a worker it forked) has loaded CasADi's CVODES plugin,
    which happens when its first integrator is built, right before integrating."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise AssertionError(f"finished before the signal: {proc.communicate()}")
        for pid in [proc.pid, *_children(proc.pid)]:
            try:
                if "casadi_integrator_cvodes" in Path(f"/proc/{pid}/maps").read_text():
                    time.sleep(0.4)     # well inside the integration
                    return
            except OSError:
                pass
        time.sleep(0.05)
    raise AssertionError("CVODES never started")


def _stop(proc: subprocess.Popen, sig: int, group: bool = False) -> tuple[int, str, str, float]:
    """Send ``sig`` (to the whole process group, as Ctrl-C in a terminal does, if
    ``group``); (exit code, stdout, stderr, seconds until the process ended)."""
    t0 = time.monotonic()
    if group:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    return proc.returncode, out, err, time.monotonic() - t0


def _leftovers(folder: Path) -> list[str]:
    """Files of ``folder`` and staging folders beside it."""
    names = [p.name for p in folder.parent.iterdir() if ".partial-" in p.name]
    if folder.exists():
        names += [str(p.relative_to(folder)) for p in folder.rglob("*")]
    return names


@linux_only
@pytest.mark.parametrize("sig, code, word", [(signal.SIGINT, 130, "interrupted"),
                                             (signal.SIGTERM, 143, "terminated")])
def test_simulate_stops_on_a_signal_inside_cvodes(tmp_path, long_recording, sig, code, word):
    # on 8c8e7dd: exit 2, "integration failed ... CvodesInterface"
    out = tmp_path / "sim"
    proc = _start(["simulate", str(PLANT), str(long_recording), "--out", str(out),
                   "--quiet", "--no-plot"])
    _wait_inside_cvodes(proc)
    rc, stdout, err, took = _stop(proc, sig)
    assert rc == code, err
    assert f"workbench simulate: {word}" in err and "integration failed" not in err
    assert "Traceback" not in err and stdout == ""
    assert _leftovers(out) == []
    assert took < 8.0            # at once: the rest of the replay takes longer


@linux_only
def test_interrupted_robustness_draw_is_not_a_failed_design(tmp_path):
    # on 8c8e7dd (--workers 1): the interrupted draw counted as failed, exit 0, files written
    out = tmp_path / "mc"
    proc = _start(["robustness", str(PLANT), "--draws", "40", "--workers", "1",
                   "--out", str(out), "--json"])
    _wait_inside_cvodes(proc)
    rc, stdout, err, _ = _stop(proc, signal.SIGINT)
    assert rc == 130, err
    assert "interrupted" in err and "Traceback" not in err
    assert stdout == ""                                   # no pass rate printed
    assert _leftovers(out) == []


@linux_only
@pytest.mark.parametrize("sig, code, group", [(signal.SIGTERM, 143, False),
                                              (signal.SIGINT, 130, True)],
                         ids=["SIGTERM to the parent", "Ctrl-C to the process group"])
def test_stopped_robustness_stops_its_workers(tmp_path, sig, code, group):
    # on 8c8e7dd: the pool waited for every queued draw before exiting, its workers
    # outlived it; with Ctrl-C in a terminal each worker printed a traceback
    out = tmp_path / "mc"
    out.mkdir()
    (out / "robustness.json").write_text("{}\n")          # an older result stays as it was
    proc = _start(["robustness", str(PLANT), "--draws", "40", "--workers", "2",
                   "--out", str(out), "--quiet"])
    _wait_inside_cvodes(proc)
    workers = _children(proc.pid)
    rc, stdout, err, took = _stop(proc, sig, group)
    assert rc == code, err
    assert ("terminated" if code == 143 else "interrupted") in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert took < 10.0                                     # 40 draws take ~30 s
    assert _leftovers(out) == ["robustness.json"]
    assert (out / "robustness.json").read_text() == "{}\n"
    time.sleep(0.2)
    alive = [w for w in workers if Path(f"/proc/{w}").exists()
             and "zombie" not in Path(f"/proc/{w}/status").read_text()]
    assert alive == []


@linux_only
def test_ctrl_c_during_the_imports_is_a_clean_stop(tmp_path, long_recording):
    # on 8c8e7dd: a traceback from inside `import workbench` (it imported everything)
    out = tmp_path / "sim"
    proc = _start(["simulate", str(PLANT), str(long_recording), "--out", str(out)])
    end = time.monotonic() + 60
    while time.monotonic() < end and proc.poll() is None:     # numpy's core is loading
        try:
            if "_multiarray_umath" in Path(f"/proc/{proc.pid}/maps").read_text():
                break
        except OSError:
            pass
        time.sleep(0.005)
    rc, stdout, err, _ = _stop(proc, signal.SIGINT)
    assert rc == 130, err
    assert "interrupted (Ctrl-C)" in err and "Traceback" not in err and stdout == ""
    assert _leftovers(out) == []


# --------------------------------------------------------------- in-process, no signal sent
def _pretend(sig: int):
    """Inside stop_on_signals, as if ``sig`` had arrived and C code had swallowed it."""
    output._RECEIVED.append(sig)


def test_fallback_replay_is_not_taken_after_an_interrupt():
    # diagnose's replay: closed loop, then open loop when the first fails. An
    # interrupted first try must stop, not fall back (issue 15: "closed loop on r" fits
    # from the other replay, exit 0)
    from workbench.replay import Fallback
    calls = []

    def first(*a):
        raise WorkbenchError("integration failed: CVode returned CV_RHSFUNC_FAIL")

    def then(*a):
        calls.append("then")

    with output.stop_on_signals():
        assert Fallback(first, then)(None, None, None) is None and calls == ["then"]
        _pretend(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt):
            Fallback(first, then)(None, None, None)
    assert calls == ["then"]


def test_robustness_outcome_after_an_interrupt_is_a_stop_not_a_failure():
    from workbench import robustness as rb

    def judge(plant, controller):
        raise RuntimeError("Error in Function::call for 'F1' [CvodesInterface]")

    rb._JOBS.update(plants=[None], controllers={"c": lambda p: None}, judge=judge)
    try:
        with output.stop_on_signals():
            assert rb._run_one(0, "c").failed == ("run",)     # a real failure fails the draw
            _pretend(signal.SIGTERM)
            with pytest.raises(output.Terminated):
                rb._run_one(0, "c")
    finally:
        rb._JOBS.clear()


def test_result_set_commits_nothing_after_a_swallowed_signal(tmp_path):
    out = tmp_path / "out"
    with output.stop_on_signals():
        _pretend(signal.SIGINT)
        with pytest.raises(KeyboardInterrupt):
            with output.result_set(out) as stage:
                (stage / "a.csv").write_text("1\n")
    assert _leftovers(out) == []
    # a new block forgets the old signal
    with output.stop_on_signals():
        assert output.interrupted() is None
        with output.result_set(out) as stage:
            (stage / "a.csv").write_text("1\n")
    assert (out / "a.csv").read_text() == "1\n"


def test_main_reports_a_swallowed_signal_as_an_interrupt(monkeypatch, capsys):
    # a command that "finishes" after C code swallowed Ctrl-C (e.g. IPOPT just stops)
    from workbench.cli import main
    from workbench.cli import plant as cli_plant

    def swallowed(args):
        _pretend(signal.SIGINT)
        return 0

    monkeypatch.setattr(cli_plant, "_check", swallowed)
    assert main(["check", str(PLANT)]) == 130
    assert "workbench check: interrupted" in capsys.readouterr().err
