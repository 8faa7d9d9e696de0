"""RRT-Connect's stall stop (``stall_iterations``): a search gives up when one tree has added no node for that
many iterations. Below the longest stall of a search it runs the same search (same path, iterations and checks);
at it, it stops as "stalled"; a walled-in goal ends early instead of at the cap; a TCBiRRT regrasp that stalls is
a failed regrasp (a counter), not an exception."""
from __future__ import annotations

import numpy as np
import pytest
from native_rrtc_case import native_or_skip, one_arm_case

from optplan.planners import make_planner
from optplan.planners.base import Deadline
from optplan.planners.rrtconnect import RRTConnectOptions, rrt_connect
from optplan.planners.tcbirrt_options import TCBiRRTOptions
from optplan.scene import Scene
from optplan.trials import TrialGenerator


def test_native_stall_stop_is_the_same_search_below_the_longest_stall_and_stops_at_it(tcb):
    """The regrasp's kind of query (one arm moving, the rest and the object still) on hard_truss: with the stop
    one iteration above the search's own longest stall the result is identical; at the longest stall the search
    ends "stalled" after fewer iterations, without a path."""
    from optplan.planners.kernel.rrtc import native_rrt_connect

    sc, tr, ck, idx, M, base, rng = one_arm_case(tcb, "hard_truss", 1)
    with ck.exempt(tuple(sorted(ck.grasp_contacts(base, M)))):
        f = ck.validity("fixed", M, base=base, joints=idx)
        goals = []
        while len(goals) < 4:
            x = rng.uniform(tcb.lower[idx], tcb.upper[idx])
            if f(x):
                goals.append(x)

        def run(goal, seed, stall):
            return native_rrt_connect(base[idx], goal, tcb.lower[idx], tcb.upper[idx], f, np.random.default_rng(seed),
                                      Deadline(60.0), range_=1.0, resolution=0.03, max_iterations=20000,
                                      stall_iterations=stall, shortcut_iterations=20)

        stalled = 0
        for k, goal in enumerate(goals):
            a = run(goal, k, 0)
            assert a is not None and a.status == "found", a and a.status
            assert sum(a.tree_nodes) == a.nodes and 0 <= a.longest_stall < a.iterations
            b = run(goal, k, a.longest_stall + 1)
            assert b.status == "found" and (b.iterations, b.nodes, b.checks) == (a.iterations, a.nodes, a.checks)
            assert np.array_equal(np.array(b.path), np.array(a.path))
            if a.longest_stall >= 1:
                c = run(goal, k, a.longest_stall)
                assert c.status == "stalled" and c.path is None and c.iterations < a.iterations
                assert c.longest_stall == a.longest_stall
                stalled += 1
        assert stalled >= 1   # at least one of the searches had a stall to stop at


def _walled_goal_case():
    """A 2-D box with the goal inside a closed square ring (unreachable) and the start outside it."""
    goal = np.array([0.7, 0.7])

    def valid(x):
        d = float(np.abs(np.asarray(x) - goal).max())
        return not (0.10 <= d <= 0.14)

    return np.array([0.1, 0.1]), goal, np.zeros(2), np.ones(2), valid


def test_python_search_gives_up_on_a_walled_in_goal():
    start, goal, lo, hi, valid = _walled_goal_case()
    st: dict = {}
    got = rrt_connect(start, goal, lo, hi, valid, np.random.default_rng(0), Deadline(60.0), range_=0.2,
                      resolution=0.01, max_iterations=20000, stats=st, stall_iterations=300)
    assert got is None and st["stalled"] == 1 and st["iterations"] < 20000
    st_off: dict = {}
    got = rrt_connect(start, goal, lo, hi, valid, np.random.default_rng(0), Deadline(60.0), range_=0.2,
                      resolution=0.01, max_iterations=3000, stats=st_off)
    assert got is None and "stalled" not in st_off and st_off["iterations"] == 3000   # without it: to the cap


def test_python_search_unchanged_by_a_stop_it_never_reaches():
    start, _, lo, hi, valid = _walled_goal_case()
    goal = np.array([0.95, 0.2])   # outside the ring: reachable
    runs = []
    for stall in (0, 10**6):
        st: dict = {}
        p = rrt_connect(start, goal, lo, hi, valid, np.random.default_rng(3), Deadline(60.0), range_=0.2,
                        resolution=0.01, max_iterations=5000, stats=st, stall_iterations=stall)
        assert p is not None
        runs.append((np.array(p), st["iterations"], st["nodes"]))
    assert np.array_equal(runs[0][0], runs[1][0]) and runs[0][1:] == runs[1][1:]


def test_options_reject_a_negative_stall():
    with pytest.raises(ValueError, match="stall_iterations.*-1"):
        RRTConnectOptions(stall_iterations=-1)
    with pytest.raises(ValueError, match="regrasp_stall_iterations.*-5"):
        TCBiRRTOptions(regrasp_stall_iterations=-5)


def test_a_stalled_regrasp_is_a_failed_regrasp_not_an_error(tcb):
    """hard_bay trial 2 needs a regrasp; with a stop after a single iteration without growth its regrasps stall
    (counted) and fail, and the query still returns a result."""
    sc = Scene.load("hard_bay")
    tr = TrialGenerator(tcb, sc).generate(2, 0)
    pl = make_planner("tcbirrt", tcb, sc, variant="improved", regrasp_stall_iterations=1)
    native_or_skip(pl.checker)
    res = pl.plan(tr.q_start, tr.q_goal, time_limit=1.0, seed=tr.seed, clock="cpu")
    st = res.stats
    assert res.status.value in ("exact", "timeout", "failed")
    assert st.get("regrasp_stalled", 0) >= 1 and st["regrasp_failures"] >= 1
    assert st["regrasp_time_s"] < 0.5   # stalled regrasps do not wait for their time limit (2 s each)
