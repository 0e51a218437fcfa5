"""The suite's own scheduling on two workers (tests/conftest.py): which tests run together,
in which order, and the check that keeps a design's quick run made once.

The rule is checked on stand-in items (a node id and marks), not by running xdist: the
groups decide where a test runs, so a wrong group costs CI time (a design run twice) or
breaks a module fixture's sharing, and neither shows as a failing test elsewhere.
"""

from __future__ import annotations

import pytest

import conftest
from conftest import _UNTIMED_S, run_design, schedule


class Item:
    """A stand-in for a collected test: its node id and its marks by name."""

    def __init__(self, nodeid: str, **marks):
        self.nodeid, self.marks = nodeid, marks

    def get_closest_marker(self, name):
        return self.marks.get(name)


def _design(name):
    return pytest.mark.design(name).mark


def test_readers_of_a_design_run_share_a_group_across_files():
    items = [Item("tests/test_a.py::t1"), Item("tests/test_a.py::t2", design=_design("p")),
             Item("tests/test_b.py::t3[x]", design=_design("p")), Item("tests/test_b.py::t4"),
             Item("tests/test_c.py::t5[1]", independent=pytest.mark.independent.mark),
             Item("tests/test_c.py::t5[2]", independent=pytest.mark.independent.mark)]
    _, groups = schedule(items, {})
    assert groups["tests/test_a.py::t2"] == groups["tests/test_b.py::t3[x]"] == "design:p"
    assert groups["tests/test_a.py::t1"] == "tests/test_a.py"        # the rest by file
    assert groups["tests/test_b.py::t4"] == "tests/test_b.py"
    # independent tests are units of their own, not their file's
    assert len({groups["tests/test_c.py::t5[1]"], groups["tests/test_c.py::t5[2]"]}) == 2


def test_heaviest_group_first_and_each_group_in_its_order():
    items = [Item("tests/test_a.py::t1"), Item("tests/test_a.py::t2"),
             Item("tests/test_b.py::t3"), Item("tests/test_c.py::t4"), Item("tests/test_c.py::t5")]
    # b is the heaviest (one slow test); a and c have no times: two untimed tests each,
    # so they tie and go by name
    times = {"tests/test_b.py::t3": 10 * _UNTIMED_S}
    order, _ = schedule(items, times)
    assert [i.nodeid for i in order] == ["tests/test_b.py::t3", "tests/test_a.py::t1",
                                         "tests/test_a.py::t2", "tests/test_c.py::t4",
                                         "tests/test_c.py::t5"]
    # a group's weight is the sum of its tests: c's two tests outweigh one timed a test
    order, _ = schedule(items, {"tests/test_a.py::t1": 1.0, "tests/test_c.py::t4": 0.8,
                                "tests/test_c.py::t5": 0.8})
    assert order[0].nodeid == "tests/test_c.py::t4"


def test_a_design_read_outside_its_group_is_refused(monkeypatch, tmp_path):
    me = "tests/test_x.py::test_reads"
    monkeypatch.setattr(conftest, "_ITEM_GROUPS", {me: "tests/test_x.py"})
    monkeypatch.setenv("PYTEST_CURRENT_TEST", f"{me} (setup)")
    with pytest.raises(RuntimeError, match=r"mark it @pytest.mark.design\('situm_p_pd'\)"):
        run_design("situm_p_pd", tmp_path / "out")
    assert not (tmp_path / "out").exists()
