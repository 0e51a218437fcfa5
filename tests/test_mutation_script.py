"""The mutation list of ``tests/mutation.py`` is not stale (no mutant is run here).

A refactor that moves or rewrites a line a mutation plants its bug in makes the
mutation silently useless; this test names it instead. Runs in well under a second.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent


def _load():
    spec = importlib.util.spec_from_file_location("_mutation_script", TESTS / "mutation.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod            # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


MUT = _load()


@pytest.mark.parametrize("m", MUT.MUTATIONS, ids=[m.name for m in MUT.MUTATIONS])
def test_original_occurs_exactly_once(m):
    path = REPO / m.file
    assert path.is_file(), f"mutation {m.name}: {m.file} does not exist"
    count = path.read_text().count(m.original)
    assert count == 1, (f"mutation {m.name}: its original text occurs {count} times in "
                        f"{m.file} (expected exactly once; update tests/mutation.py): "
                        f"{m.original!r}")
    assert m.replacement != m.original


def test_list_is_well_formed():
    names = [m.name for m in MUT.MUTATIONS]
    assert len(names) == len(set(names)), "mutation names must be unique"
    assert len(names) >= 40                       # the issue-17 brief asks for at least 40
    assert {m.group for m in MUT.MUTATIONS} <= set(MUT.GROUPS)
    for m in MUT.MUTATIONS:
        assert m.tests, f"mutation {m.name} names no tests"
        assert all(t.startswith("tests/test_") for t in m.tests), m.name
        have, _ = MUT.present_tests(m)
        assert have, f"mutation {m.name}: none of its test files exists"
    assert MUT.stale(MUT.MUTATIONS) == []


def test_stale_check_catches_a_moved_line(tmp_path):
    """The checker itself: a mutation whose text is gone, or occurs twice, is reported."""
    (tmp_path / "workbench").mkdir()
    (tmp_path / "workbench" / "f.py").write_text("a = b - c\nx = y\nx = y\n")
    ok = MUT.Mutation("ok", "physics", "workbench/f.py", "b - c", "b + c", "", ("tests/t.py",))
    gone = MUT.Mutation("gone", "physics", "workbench/f.py", "b * c", "b / c", "", ("tests/t.py",))
    twice = MUT.Mutation("twice", "physics", "workbench/f.py", "x = y", "x = -y", "",
                         ("tests/t.py",))
    problems = MUT.stale([ok, gone, twice], root=tmp_path)
    assert len(problems) == 2
    assert problems[0].startswith("gone: original text occurs 0 times")
    assert problems[1].startswith("twice: original text occurs 2 times")


def test_issue_17_mutations_are_listed():
    """The eight (nine lines) surviving bugs of issue 17 are all in the list."""
    names = {m.name for m in MUT.MUTATIONS}
    assert {"supply-leak-reversed", "four-edge-exhaust-b-temperature", "dbic-penalty-sign",
            "gain-over-j", "arx-variance-n", "arx-fpe-inverted", "inversion-symbolic-factor",
            "command-for-gamma-saturation", "limits-sampled-frequency"} <= names
