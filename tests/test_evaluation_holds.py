"""DesignEvaluation's judgement of the holds (issue 14: "no limit cycle in any hold").

A hold is at rest when, over its second half, the position's peak-to-peak is within one
quantum and the command changed at most LOCK_EVENTS times (the valve closing once is
two changes). The cases sit on each side of both limits, so a `<` for `<=`, an `or` for
`and`, or a dropped condition turns one of them red.
"""

import numpy as np

from workbench.controllers.evaluation import LOCK_EVENTS, DesignEvaluation

Q = 1.22e-4  # m: a 12-bit quantum on a 0.5 m stroke


def _ev(holds):
    return DesignEvaluation(kind="nmpc", controller=None, validation=None,
                            update_times=np.array([1e-4]), holds=holds, quantum=Q,
                            pressure_noise=300.0, limits=None)


def _hold(name, ptp, changes):
    return {"segment": name, "peak_to_peak": ptp, "command_changes": changes, "quantum": Q}


def test_holds_within_both_limits_are_at_rest():
    ev = _ev([_hold("a", Q, LOCK_EVENTS), _hold("b", 0.0, 0)])
    assert ev.limit_cycle_free and ev.holds_not_at_rest == []


def test_a_hold_beyond_either_limit_is_named():
    holds = [_hold("ok", 0.5 * Q, 0), _hold("walks", 1.77 * Q, 10),
             _hold("chatters", 0.0, LOCK_EVENTS + 1), _hold("drifts", 1.01 * Q, 0)]
    ev = _ev(holds)
    assert not ev.limit_cycle_free
    assert [h["segment"] for h in ev.holds_not_at_rest] == ["walks", "chatters", "drifts"]
