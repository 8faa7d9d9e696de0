"""Trap grafts of TCBiRRT (``TCBiRRTOptions.trap_grafts``): after a node's ``trap_graft_count``-th trapped
extension, the arms re-grasp at that node into an IK solution from which one constrained step passes
(:func:`optplan.planners.frontier_graft.lookahead_graft`). Checked against Pinocchio FK (the closed chain),
the checker's exact collision queries at every configuration and the bench's 1 cm sweep spacing along every
straight edge."""
from __future__ import annotations

import numpy as np
import pytest
from graft_paths import (
    check_graft_node,
    check_planned_path,
    extension_stats,
    task_tree,
    truss_case,
)

from optplan.planners import TCBiRRT, TCBiRRTOptions
from optplan.planners.base import Deadline


@pytest.fixture(scope="module")
def truss(tcb):
    return truss_case(tcb)


def test_trap_graft_fires_once_at_the_count_and_steps_toward_the_other_tree(tcb, truss):
    """A node's trapped extensions are counted; only the ``trap_graft_count``-th tries a graft (never before, and
    not again for that node). The graft found at the start of a truss trial: a configuration at the start's pose
    that closes the chain, is free and is not the start's (beyond one restart's joint step), joined to the start by
    one-arm regrasp motions with the object fixed; below it a node one step (``step_size`` in ξ) toward the other
    tree's nearest node, every edge passing the 1 cm sweep check."""
    scene, ck, kin, gen = truss
    t = gen.generate(6, 0)
    count = 3
    pl = TCBiRRT(tcb, scene, TCBiRRTOptions(variant="improved", trap_grafts=4, trap_graft_count=count,
                                            trap_graft_target="other", trap_graft_stream="search"), checker=ck,
                 kinematics=kin)
    pl._rng = np.random.default_rng(3)
    b = task_tree(kin, t.q_goal)
    xi_far = np.full(6, 9.0)   # the trapping sample: unused with trap_graft_target="other"
    n, tries = None, 0
    while n is None and tries < 10:   # a fresh tree and counter per try: the graft's random seeds may all fail
        a, st, trap = task_tree(kin, t.q_start), extension_stats(), [0]
        for k in range(1, count):
            assert pl._trap_graft(a, 0, xi_far, b, trap, Deadline(5.0, "cpu"), st) is None
            assert "trap_attempts" not in st and a.trapn[0] == k   # the node's count, in its tree
        n = pl._trap_graft(a, 0, xi_far, b, trap, Deadline(5.0, "cpu"), st)
        assert st["trap_attempts"] == 1
        assert pl._trap_graft(a, 0, xi_far, b, trap, Deadline(5.0, "cpu"), st) is None and st["trap_attempts"] == 1
        tries += 1
    assert n is not None and trap[0] == 1 and st["trap_grafts"] == 1
    check_graft_node(pl, tcb, scene, ck, kin, t.q_start, a, b, n)


def test_trap_graft_options_are_checked():
    o = TCBiRRTOptions(variant="paper")
    assert o.trap_grafts == 0 and o.trap_graft_count == 20 and o.trap_graft_target == "other"
    assert o.trap_graft_after == 0 and o.trap_graft_stream == "search"
    o = TCBiRRTOptions(variant="improved")   # decided on fresh seed 16001 (docs/generalization.md)
    assert o.trap_grafts == 4 and o.trap_graft_count == 20 and o.trap_graft_target == "sample"
    assert o.trap_graft_after == 1500 and o.trap_graft_stream == "own"
    assert TCBiRRTOptions(variant="improved", trap_grafts=3).trap_grafts == 3
    assert TCBiRRTOptions(variant="improved", trap_graft_after=1500).trap_graft_after == 1500
    for bad in (dict(trap_grafts=-1), dict(trap_grafts=1.5), dict(trap_graft_count=0), dict(trap_graft_target="goal"),
                dict(trap_graft_after=-1), dict(trap_graft_after=2.5), dict(trap_graft_after=True),
                dict(trap_graft_stream="shared")):
        with pytest.raises(ValueError, match=next(iter(bad))):
            TCBiRRTOptions(**bad)


def test_planner_with_trap_grafts_returns_a_verified_path(tcb, truss):
    """The search with trap grafts after 5 traps of a node (branch and frontier grafts off) on a truss trial whose
    trees stop at the grid from either side: trap grafts are tried, and the path runs from start to goal, its
    constrained configurations close the chain (Pinocchio FK) and are free, and every straight edge passes the
    bench's independent 1 cm sweep check."""
    scene, ck, kin, gen = truss
    t = gen.generate(18, 0)
    pl = TCBiRRT(tcb, scene, TCBiRRTOptions(variant="improved", branch_grafts=0, frontier_grafts=0, trap_grafts=4,
                                            trap_graft_count=5, trap_graft_target="other", trap_graft_stream="search",
                                            trap_graft_after=0), checker=ck, kinematics=kin)
    res = pl.plan(t.q_start, t.q_goal, time_limit=30.0, seed=t.seed, clock="cpu")
    assert res.success, res.message
    assert res.stats["trap_attempts"] >= 1 and res.stats["grafts"] == 0 and "frontier_attempts" not in res.stats
    check_planned_path(tcb, scene, ck, res, t.q_start, t.q_goal)


def _same_search(r0, r1) -> None:
    """Two results of the same search: status, path, object poses and every counter but the clocks."""
    assert r0.status == r1.status and r0.path.shape == r1.path.shape and np.array_equal(r0.path, r1.path)
    assert np.array_equal(r0.constrained, r1.constrained)
    clocks = {k for k in set(r0.stats) | set(r1.stats) if k.endswith("time_s")}
    assert {k: v for k, v in r0.stats.items() if k not in clocks} == {k: v for k, v in r1.stats.items() if k not in clocks}


@pytest.mark.parametrize("trial, max_iterations", [(6, 0), (18, 300)])
def test_no_trap_graft_before_trap_graft_after(tcb, truss, trial, max_iterations):
    """A search that ends by ``trap_graft_after`` is the search with trap grafts off — the same path, iterations
    and counters, though a trap graft would fire at a node's first trapped extension (``trap_graft_count=1``):
    truss trial 6 is solved in about 1,000 iterations, trial 18 is cut at 300 (lead paths off, so that no step
    depends on the clock). With the start earlier than the search's end, trap grafts are attempted."""
    scene, ck, kin, gen = truss
    t = gen.generate(trial, 0)

    def plan(**kw):
        o = TCBiRRTOptions(variant="improved", guide_probability=0.0, trap_graft_count=1,
                           max_iterations=max_iterations, **kw)
        return TCBiRRT(tcb, scene, o, checker=ck, kinematics=kin).plan(t.q_start, t.q_goal, time_limit=30.0,
                                                                        seed=t.seed, clock="cpu")
    off = plan(trap_grafts=0)
    n = off.stats["iterations"]
    assert off.stats["trapped"] > 100 and "trap_attempts" not in off.stats
    assert off.success == (max_iterations == 0) and n >= 300
    _same_search(off, plan(trap_grafts=4, trap_graft_after=n))
    late = plan(trap_grafts=4, trap_graft_after=n // 2)
    assert late.stats["trap_attempts"] >= 1


def test_trap_graft_own_stream_leaves_the_search_when_attempts_fail(tcb, truss):
    """With ``trap_graft_stream="own"`` a trap-graft attempt draws from the tree's own random streams, so a search
    whose attempts all fail (here: a truss trial cut at 300 iterations, lead paths off so that no step depends on
    the clock) is the search with trap grafts off — the same path and iterations, extensions, trapped extensions,
    nodes — although attempts were made; the default stream's attempts change the search's random stream."""
    scene, ck, kin, gen = truss
    t = gen.generate(18, 0)

    def plan(**kw):
        o = TCBiRRTOptions(variant="improved", guide_probability=0.0, trap_graft_count=1, max_iterations=300,
                           trap_graft_after=0, **kw)
        return TCBiRRT(tcb, scene, o, checker=ck, kinematics=kin).plan(t.q_start, t.q_goal, time_limit=30.0,
                                                                        seed=t.seed, clock="cpu")
    off = plan(trap_grafts=0)
    own = plan(trap_grafts=4, trap_graft_target="sample", trap_graft_stream="own")
    assert own.stats["trap_attempts"] >= 5 and own.stats.get("trap_grafts", 0) == 0
    assert own.status == off.status and np.array_equal(own.path, off.path)
    for k in ("iterations", "extensions", "trapped", "partial", "grafts", "graft_attempts"):
        assert own.stats[k] == off.stats[k], k
    shared = plan(trap_grafts=4, trap_graft_target="sample", trap_graft_stream="search")
    assert shared.stats["trap_attempts"] >= 1
    assert any(shared.stats[k] != off.stats[k] for k in ("extensions", "trapped", "partial"))
