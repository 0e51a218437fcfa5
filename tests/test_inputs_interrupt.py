"""Ctrl-C in the middle of the two long commands, diagnose and design (session 12):
exit 130, one line saying so, no traceback, no worker left running, and the output
folder exactly as it was (an earlier result in it kept byte for byte, no staging
folder beside it).

Real signals to a real ``workbench`` process group (the helpers of
tests/test_interrupt.py), sent once the computation runs: for design, once its
validation is inside CVODES; for diagnose (whose replays step their own integrators),
once it has started its worker processes for the candidate refits, or after 20 s.
"""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

from test_interrupt import (PLANT, _children, _leftovers, _start, _stop,  # noqa: F401
                            _wait_inside_cvodes, linux_only, long_recording)


def _group_alive(pid: int) -> list[int]:
    """Processes still in the process group ``pid`` (a terminal's job)."""
    alive = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            fields = (proc / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pid and fields[0] != "Z":     # pgrp, state (not a zombie)
            alive.append(int(proc.name))
    return alive


def _wait_for_workers(proc, timeout: float = 20.0) -> None:
    """Until ``proc`` has child processes (diagnose's refit pool) or ``timeout`` s;
    it must still be running then."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and not _children(proc.pid):
        assert proc.poll() is None, f"finished before the signal: {proc.communicate()}"
        time.sleep(0.05)
    time.sleep(0.4)
    assert proc.poll() is None, f"finished before the signal: {proc.communicate()}"


def _interrupt(args: list[str], out: Path, wait=_wait_inside_cvodes) -> None:
    out.mkdir()
    (out / "diagnosis.json").write_text('{"an": "earlier result"}')
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    proc = _start(args)
    wait(proc)
    code, _, err, _ = _stop(proc, signal.SIGINT, group=True)
    assert code == 130, err
    assert "Traceback" not in err, err
    assert err.strip().splitlines()[-1].endswith(": interrupted (Ctrl-C)"), err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert [n for n in _leftovers(out) if n != "diagnosis.json"] == []
    end = time.monotonic() + 10.0        # workers get the same Ctrl-C: gone in moments
    while _group_alive(proc.pid) and time.monotonic() < end:
        time.sleep(0.1)
    assert _group_alive(proc.pid) == []


@linux_only
def test_ctrl_c_in_diagnose_leaves_nothing(tmp_path, long_recording):
    _interrupt(["diagnose", str(PLANT), str(long_recording), "--out", str(tmp_path / "out"),
                "--quiet"], tmp_path / "out", wait=_wait_for_workers)


@linux_only
def test_ctrl_c_in_design_leaves_nothing(tmp_path):
    _interrupt(["design", str(PLANT), "--kind", "pid", "--quick", "--out",
                str(tmp_path / "out")], tmp_path / "out")
