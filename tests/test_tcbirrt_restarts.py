"""TCBiRRT's restarts (``restart_iterations``, ``restart_growth``, ``restart_branch_roots``): the iteration schedule,
every second search with branch-consistent roots, the counters summed
over the searches, the same search as without restarts until the first restart, and a path found after restarts
checked independently (Pinocchio FK for the closed chain, the checker at every configuration and the bench's 1 cm
sweep along every straight edge)."""
from __future__ import annotations

import numpy as np
import pytest
from graft_paths import check_planned_path

from optplan.planners import TCBiRRT, TCBiRRTOptions, ValidityChecker
from optplan.planners.base import PlanStatus
from optplan.scene import Scene
from optplan.trials import TrialGenerator


@pytest.fixture(scope="module")
def truss(tcb):
    sc = Scene.load("hard_truss")
    return sc, ValidityChecker(tcb, sc), TrialGenerator(tcb, sc).generate(1, 0)


@pytest.fixture(scope="module")
def ssps(tcb):
    sc = Scene.load("ssps_scene1")
    return sc, ValidityChecker(tcb, sc), TrialGenerator(tcb, sc).generate(0, 0)


def test_restart_schedule_and_summed_counters(tcb, truss):
    """Budgets 5, 10, 20 and the 5 left of ``max_iterations`` = 40: three restarts, 40 iterations in all (the truss
    is not solved in 5-20 iterations); the nodes of the four searches add up."""
    sc, ck, t = truss
    o = TCBiRRTOptions(variant="improved", restart_iterations=5, restart_growth=2.0, max_iterations=40,
                       restart_branch_roots=True)
    res = TCBiRRT(tcb, sc, o, checker=ck).plan(t.q_start, t.q_goal, time_limit=60.0, seed=3, clock="cpu")
    assert res.status == PlanStatus.FAILED and "iteration cap" in res.message
    assert res.stats["restarts"] == 3 and res.stats["iterations"] == 40
    # the 4th search (the 3rd restart) is one of every second: its goal root re-grasped onto the start's branch
    assert "root_branch" in res.stats
    no_flip = TCBiRRTOptions(variant="improved", restart_iterations=5, restart_growth=2.0, max_iterations=40,
                             restart_branch_roots=False)
    plain = TCBiRRT(tcb, sc, no_flip, checker=ck).plan(t.q_start, t.q_goal, time_limit=60.0, seed=3, clock="cpu")
    assert plain.stats["restarts"] == 3 and "root_branch" not in plain.stats
    one = TCBiRRT(tcb, sc, TCBiRRTOptions(variant="improved", restart_iterations=0, max_iterations=5), checker=ck)
    first = one.plan(t.q_start, t.q_goal, time_limit=60.0, seed=3, clock="cpu")
    assert first.stats["iterations"] == 5 and "restarts" not in first.stats
    # every search starts with its two roots: at least 2 nodes each, and more nodes than the first search alone
    assert res.stats["nodes"] >= 4 * 2 and res.stats["nodes"] > first.stats["nodes"]


def test_same_search_as_without_restarts_before_the_first(tcb, ssps):
    """A query solved within the first budget gives the identical path with and without restarts."""
    sc, ck, t = ssps
    paths = []
    for r in (0, 4000):
        o = TCBiRRTOptions(variant="improved", restart_iterations=r, extension="python")
        res = TCBiRRT(tcb, sc, o, checker=ck).plan(t.q_start, t.q_goal, time_limit=60.0, seed=0, clock="cpu")
        assert res.success and res.stats["iterations"] < 4000
        assert res.stats.get("restarts", 0) == 0
        paths.append(res.path)
    assert paths[0].shape == paths[1].shape and np.array_equal(paths[0], paths[1])


def test_path_found_after_restarts_is_valid(tcb, ssps):
    """Budgets of 3 iterations growing 1.5× per restart: the search restarts, and the path it returns closes the
    chain, is free and passes the 1 cm sweep (no node of an abandoned search leaks into it)."""
    sc, ck, t = ssps
    o = TCBiRRTOptions(variant="improved", restart_iterations=3, restart_growth=1.5, restart_branch_roots=True)
    res = TCBiRRT(tcb, sc, o, checker=ck).plan(t.q_start, t.q_goal, time_limit=60.0, seed=1, clock="cpu")
    assert res.success, res.message
    assert res.stats["restarts"] >= 1
    check_planned_path(tcb, sc, ck, res, t.q_start, t.q_goal)


def test_restart_options_are_checked():
    assert TCBiRRTOptions().restart_iterations == 0 and TCBiRRTOptions().restart_branch_roots is False
    # measured on fresh generated scenes and left off in both variants (docs/planners.md)
    assert TCBiRRTOptions(variant="improved").restart_iterations == 0
    assert TCBiRRTOptions(variant="improved").restart_branch_roots is False
    o = TCBiRRTOptions(variant="improved", restart_iterations=5000, restart_branch_roots=True)
    assert o.restart_iterations == 5000 and o.restart_branch_roots is True and o.restart_growth == 1.5
    for bad in (dict(restart_iterations=-1), dict(restart_iterations=2.5), dict(restart_growth=0.5),
                dict(restart_growth=float("inf")), dict(restart_branch_roots=1)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            TCBiRRTOptions(**bad)
