"""Tree balancing (VAMP's tree ratio) in the Python RRT-Connect, and the regrasp motions' balance option of TCBiRRT:
valid seeded paths, a ratio that never binds gives the plain search, the option reaches the regrasp's RRT-Connect."""
from __future__ import annotations

import numpy as np
import pytest

from optplan.planners import make_planner
from optplan.planners.rrtconnect import RRTConnectOptions, edge_is_valid
from optplan.planners.tcbirrt_options import TCBiRRTOptions
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene
from optplan.trials import TrialGenerator


def _coal_valid(robot, scene, P) -> bool:
    f = ValidityChecker(robot, scene, kernel="coal").validity("free")
    return bool(f(P[0])) and all(edge_is_valid(a, b, f, 0.004) for a, b in zip(P[:-1], P[1:]))


def test_python_search_with_balance_gives_valid_seeded_paths(tcb):
    sc = Scene.load("hard_clutter_dense")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    pl = make_planner("rrtconnect", tcb, sc, max_iterations=20000, shortcut_iterations=0, native_search=False,
                      balance=1.0)
    a, b = (pl.plan(tr.q_start, tr.q_goal, time_limit=120, seed=s) for s in (5, 5))
    assert a.status.value == "exact" and a.stats["search"] == "python"
    assert np.array_equal(a.path, b.path) and a.stats["iterations"] == b.stats["iterations"]
    assert np.all(np.linalg.norm(np.diff(a.path, axis=0), axis=1) <= pl.options.range * (1 + 1e-9))
    assert _coal_valid(tcb, sc, a.path)


def test_python_balance_that_never_binds_is_the_plain_search_and_one_that_binds_is_not(tcb):
    sc = Scene.load("hard_bay")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    out = {}
    for ratio in (0.0, 1e9, 1.0):
        pl = make_planner("rrtconnect", tcb, sc, max_iterations=400, shortcut_iterations=0, native_search=False,
                          balance=ratio)
        out[ratio] = pl.plan(tr.q_start, tr.q_goal, time_limit=120, seed=11)
    a, b, c = out[0.0], out[1e9], out[1.0]
    assert a.status == b.status and a.stats["iterations"] == b.stats["iterations"]
    assert a.stats["nodes"] == b.stats["nodes"] and np.array_equal(a.path, b.path)
    assert (c.stats["iterations"], c.stats["nodes"]) != (a.stats["iterations"], a.stats["nodes"])


def test_balance_is_allowed_without_the_native_search():
    assert RRTConnectOptions(balance=1.0, native_search=False).balance == 1.0
    for bad in ({"dynamic_domain": 2.0, "native_search": False}, {"connect": "new", "native_search": False}):
        with pytest.raises(ValueError, match="native search"):
            RRTConnectOptions(**bad)


def test_regrasp_balance_option_values_and_errors():
    assert TCBiRRTOptions(variant="paper").regrasp_balance == 0.0
    assert TCBiRRTOptions(variant="improved", regrasp_balance=2.0).regrasp_balance == 2.0
    for bad in (-1.0, float("nan"), "1", True):
        with pytest.raises(ValueError, match="TCBiRRTOptions.regrasp_balance"):
            TCBiRRTOptions(regrasp_balance=bad)


@pytest.mark.parametrize("ratio,own", [(1.0, 0.0), (0.0, 0.0), (1.0, 3.0)])
def test_regrasp_motions_get_the_balance(tcb, monkeypatch, ratio, own):
    """The regrasp's RRT-Connect runs with regrasp_balance when its own options leave balance at 0, and with its own
    value otherwise (a truss query, whose search regrasps)."""
    import optplan.planners.regrasp as rg

    seen: list[float] = []
    real = rg.joint_space_path

    def spy(*a, **k):
        seen.append(a[7].balance)
        return real(*a, **k)

    monkeypatch.setattr(rg, "joint_space_path", spy)
    sc = Scene.load("hard_truss")
    gen = TrialGenerator(tcb, sc)
    pl = make_planner("tcbirrt", tcb, sc, variant="improved", regrasp_balance=ratio,
                      regrasp=RRTConnectOptions(range=1.0, resolution=0.03, shortcut_iterations=50, balance=own),
                      max_iterations=3000)
    for trial in range(6):   # the first trials whose search regrasps
        tr = gen.generate(trial, 0)
        pl.plan(tr.q_start, tr.q_goal, time_limit=60, seed=tr.seed, clock="cpu")
        if seen:
            break
    assert seen, "no query made a regrasp motion"
    assert set(seen) == {own if own else ratio}
