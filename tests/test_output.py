"""workbench.output: result sets whole or not at all, inputs never overwritten."""

from __future__ import annotations

import os

import pytest

from workbench.errors import InputError
from workbench.output import Terminated, check_output_dir, result_set


def test_new_folder_appears_only_on_success(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        with result_set(out) as stage:
            (stage / "a.csv").write_text("x")
            raise KeyboardInterrupt
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []          # no staging folder left behind


def test_existing_folder_keeps_old_files_on_terminate(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "a.csv").write_text("old")
    (out / "keep.txt").write_text("user's")
    with pytest.raises(Terminated):
        with result_set(out) as stage:
            (stage / "a.csv").write_text("new")
            (stage / "b.csv").write_text("new")
            raise Terminated
    assert sorted(p.name for p in out.iterdir()) == ["a.csv", "keep.txt"]
    assert (out / "a.csv").read_text() == "old"
    with result_set(out) as stage:
        (stage / "a.csv").write_text("new")
        (stage / "sub").mkdir()
        (stage / "sub" / "c.txt").write_text("c")
    assert (out / "a.csv").read_text() == "new"
    assert (out / "sub" / "c.txt").read_text() == "c"
    assert (out / "keep.txt").read_text() == "user's"
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_input_is_never_overwritten(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    rec = out / "simulation.csv"
    rec.write_text("t,x\n0,0\n")
    with pytest.raises(InputError, match="overwrite the input"):
        with result_set(out, inputs=[rec]) as stage:
            (stage / "simulation.csv").write_text("t,x\n0,1\n")
    assert rec.read_text() == "t,x\n0,0\n"


@pytest.mark.parametrize("make, pattern", [
    (lambda d: "", "empty"),
    (lambda d: ((d / "f").write_text(""), d / "f")[1], "not a folder"),
    (lambda d: ((d / "f").write_text(""), d / "f" / "sub")[1], "is a file"),
])
def test_bad_output_folder_is_refused_before_work(tmp_path, make, pattern):
    with pytest.raises(InputError, match=pattern):
        check_output_dir(make(tmp_path))


def test_unwritable_output_folder_is_refused(tmp_path, monkeypatch):
    # os.access is patched, not chmod: the CI may run as root, who may write anywhere
    ro = tmp_path / "ro"
    ro.mkdir()
    monkeypatch.setattr(os, "access", lambda path, mode: os.fspath(path) != os.fspath(ro))
    with pytest.raises(InputError, match="permission denied"):
        check_output_dir(ro / "run")
