"""The work budgets of TCBiRRT's sub-searches (``regrasp_iterations``, ``graft_iterations``, ``guide_iterations``,
``guide_attempt_iterations``): a query whose lead-path attempt runs out of its budget, and one whose regrasps fail
at theirs, run the same search (iterations, nodes, counters, path) when the clock of the planner's deadlines runs
five times faster (the overall limit large): the seconds limits are backstops that do not bind. The
``Deadline`` work budget itself (shares, spending up the chain, the iteration cap), the backoff's halving of the
budget, and the options' validation."""
from __future__ import annotations

import math
import re
import time

import numpy as np
import pytest

from optplan.planners import TCBiRRT, TCBiRRTOptions, ValidityChecker
from optplan.planners.base import Deadline
from optplan.scene import Scene
from optplan.trials import TrialGenerator

FAST = 5.0   # seconds of the patched clock per CPU second


def _fast_clock(monkeypatch: pytest.MonkeyPatch) -> None:
    """The "cpu" clock of the planner's deadlines runs FAST times faster, in Python and in the native searches
    (which read the end time on their own clock: the time left is handed to them in real seconds)."""
    import optplan.planners.base as base
    import optplan.planners.kernel.rrtc as rrtc
    import optplan.planners.kernel.sampler as sampler

    t0 = time.process_time()
    monkeypatch.setitem(base.CLOCKS, "cpu", lambda: t0 + FAST * (time.process_time() - t0))
    native = lambda d: (1, time.process_time() + max(0.0, d.remaining()) / FAST)   # noqa: E731
    monkeypatch.setattr(rrtc, "_clock", native)
    monkeypatch.setattr(sampler, "_clock", native)


def _run(tcb, scene_name: str, trial: int, **opts):
    sc = Scene.load(scene_name)
    t = TrialGenerator(tcb, sc).generate(trial, 0)
    pl = TCBiRRT(tcb, sc, TCBiRRTOptions(variant="improved", **opts), checker=ValidityChecker(tcb, sc))
    return pl.plan(t.q_start, t.q_goal, time_limit=1e4, seed=t.seed, clock="cpu")


KEYS = ("iterations", "nodes", "extensions", "regrasp_attempts", "regrasp_failures", "regrasp_iterations",
        "regrasp_nodes", "guide_attempts", "guide_iterations", "guide_waypoints", "graft_attempts", "grafts")


def _same_search(a, b) -> None:
    assert a.status == b.status
    assert {k: a.stats.get(k) for k in KEYS} == {k: b.stats.get(k) for k in KEYS}
    assert np.array_equal(np.asarray(a.path), np.asarray(b.path))


def test_lead_path_out_of_budget_same_search_on_a_fast_clock(tcb, monkeypatch):
    """``hard_window`` trial 78 of seed 0 (where two runs of the seconds-bounded code diverged): the first lead-path
    attempt runs out of ``guide_attempt_iterations``; with the defaults the search is the same on a clock 5x fast."""
    a = _run(tcb, "hard_window", 78, max_iterations=1500)
    assert a.stats["guide_attempts"] >= 2   # an attempt ran out of its budget
    _fast_clock(monkeypatch)
    b = _run(tcb, "hard_window", 78, max_iterations=1500)
    _same_search(a, b)


def test_failing_regrasps_same_search_on_a_fast_clock(tcb, monkeypatch):
    """Small regrasp and graft budgets (and lead-path ones) so that regrasps fail at them: the same search on a
    clock 5x fast."""
    opts = dict(max_iterations=600, regrasp_iterations=40, graft_iterations=40, guide_attempt_iterations=200,
                guide_iterations=1000, graft_after=100, graft_interval=50)
    a = _run(tcb, "hard_window", 5, **opts)
    assert a.stats["regrasp_failures"] >= 1 and a.stats["guide_attempts"] >= 2
    _fast_clock(monkeypatch)
    b = _run(tcb, "hard_window", 5, **opts)
    _same_search(a, b)


def test_deadline_work_budget():
    d = Deadline(60.0, "cpu")
    assert d.work == math.inf and d.work_cap() == 0 and not d.expired()
    s = d.sub(30.0, 100)
    s2 = s.sub(30.0, s.work / 2)               # a share of what is left
    assert (s.work, s2.work, s2.work_cap()) == (100, 50, 50)
    s2.spend(49.5)
    assert (s2.work, s.work, d.work) == (0.5, 50.5, math.inf) and s2.work_cap() == 1 and not s2.expired()
    s2.spend(1)
    assert s2.expired() and not s.expired() and not d.expired()
    assert s.sub(30.0, 1e6).work == 49.5       # never more than the enclosing budget
    assert Deadline(60.0).sub(0.0, 10).expired()   # the seconds still end it


def test_backoff_halves_the_work_budget(tcb, rng):
    from optplan.planners import make_planner

    scene = Scene.load("ssps_scene1")
    tr = TrialGenerator(tcb, scene).generate(0, 0)
    pl = make_planner("tcbirrt", tcb, scene, variant="improved", regrasp_backoff=True, regrasp_iterations=800,
                      regrasp_min_iterations=150)
    M = pl.kin.object_pose(tr.q_start)
    for _ in range(300):
        x, _ = pl.kin.ik(rng.uniform(pl.robot.lower, pl.robot.upper), M.rotation, M.translation, pl.options.ik)
        if x is not None and all(np.abs(x[i] - tr.q_start[i]).max() > 0.3 for i in pl.kin.idx):
            break
    seen: list[float] = []
    pl._regrasp_orders = lambda *a, **k: seen.append(a[5].work)   # records the budget, fails
    st = {"regrasp_attempts": 0, "regrasp_failures": 0, "regrasp_nodes": 0, "edge_collisions": 0}
    for _ in range(4):
        assert pl.regrasp(tr.q_start, x, M.rotation, M.translation, rng, Deadline(60.0), st) is None
    assert seen == [800, 400, 200, 150]


@pytest.mark.parametrize("name", ["regrasp_iterations", "regrasp_min_iterations", "graft_iterations",
                                  "guide_iterations", "guide_attempt_iterations"])
@pytest.mark.parametrize("bad", [-1, 2.5, True, "100", None])
def test_budget_validation(name, bad):
    with pytest.raises(ValueError, match=f"{name}.*{re.escape(repr(bad))}"):
        TCBiRRTOptions(**{name: bad})
    assert getattr(TCBiRRTOptions(**{name: 0}), name) == 0   # 0: no budget
