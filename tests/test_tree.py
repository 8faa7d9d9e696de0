"""The one RRT tree (optplan.planners.tree.Tree) against brute force, and the planners that grow it
(OC-RRT, CBiRRT2, TCBiRRT, RRT-Connect) against their node counts and paths on fixed seeds
recorded with the per-planner tree classes this tree replaced (same results, node for node)."""
from __future__ import annotations

import numpy as np
import pytest

from optplan.planners.tree import Tree


def test_tree_matches_brute_force():
    rng = np.random.default_rng(7)
    X = rng.normal(size=(700, 5))
    t = Tree(X[0], cap=4, P=np.zeros(2), edges=True)
    parents = [-1]
    for k in range(1, len(X)):                       # grows 4 -> 1024 through 8 doublings
        p = int(rng.integers(k))
        assert t.add(X[k], p, edge=[X[k] * 0.5], P=np.full(2, k)) == k
        parents.append(p)
    assert len(t) == 700 and t.X.shape[0] == 1024 and t.P.shape == (1024, 2)
    assert np.array_equal(t.P[:700, 0], np.arange(700)) and t.P[0, 0] == 0
    for x in rng.normal(size=(50, 5)):
        assert t.nearest(x) == min(range(700), key=lambda i: float(np.sum((X[i] - x) ** 2)))
    i = 699
    chain = []
    while i >= 0:
        chain.append(i)
        i = parents[i]
    assert t.indices(699) == chain[::-1]
    br = t.branch(699)
    expect = []
    for k in chain[::-1]:
        if k:
            expect.append(X[k] * 0.5)
        expect.append(X[k])
    assert len(br) == len(expect) and all(np.array_equal(a, b) for a, b in zip(br, expect))
    assert [int(v[0]) for v in t.branch(699, "P")] == chain[::-1]


def test_tree_kill_removes_subtrees_from_the_search():
    t = Tree(np.zeros(2))
    a = t.add(np.array([1.0, 0]), 0)
    b = t.add(np.array([2.0, 0]), a)
    c = t.add(np.array([0, 1.0]), 0)
    assert t.nearest(np.array([2.1, 0])) == b
    assert t.kill(a) == 2 and t.n_dead == 2
    assert t.nearest(np.array([2.1, 1.0])) == c
    assert np.array_equal(t.live_keys(), np.array([[0, 0], [0, 1.0]]))
    d = t.add(np.array([3.0, 0]), c)                 # later nodes are alive
    assert t.nearest(np.array([2.9, 0])) == d


def test_tree_bad_input():
    with pytest.raises(ValueError, match="1-D root"):
        Tree(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="capacity"):
        Tree(np.zeros(2), cap=0)


# The searches below were recorded with the Python regrasp RRT-Connect; the native one (the default when the
# checks are native) draws its own random stream, so these tests keep the Python search.
PY_REGRASP = {"range": 1.0, "resolution": 0.03, "shortcut_iterations": 50, "native_search": False, "balance": 0.0}

# (status, nodes, path length, sum |q| over the path) recorded before the planners shared this tree
GOLDEN_TCB = {
    ("paper", 0): ("exact", 14, 44, 998.1059733565778),
    ("improved", 0): ("exact", 46, 67, 1579.6599190482893),
    ("paper", 1): ("exact", 34, 68, 1547.464026634825),
    ("improved", 1): ("exact", 42, 55, 1226.9088350001152),
}
# PR2 entries re-recorded 2026-11-24 when the collision hulls became real convex hulls (and the
# passageway goal moved out of its plate): the collision verdicts changed, not the planners
GOLDEN_PR2 = {
    ("oc_industrial_1", "oc_rrt", 0): ("failed", 329, None, None),
    ("oc_industrial_1", "oc_rrt", 1): ("failed", 399, None, None),
    ("oc_industrial_1", "oc_rrt_connect", 1): ("exact", 140, 24, 398.0634025712112),
    ("oc_industrial_1", "cbirrt", 0): ("exact", 102, 155, 2403.984080305992),
    ("oc_passageway", "oc_rrt", 0): ("exact", 78, 10, 153.5553649142587),
    ("oc_passageway", "oc_rrt_connect", 0): ("exact", 133, 23, 407.66706649457717),
    ("oc_passageway", "cbirrt", 1): ("failed", 1180, None, None),
    ("oc_industrial_2", "oc_rrt", 0): ("failed", 370, None, None),
    ("oc_industrial_2", "oc_rrt_connect", 0): ("exact", 71, 16, 300.00509471079545),
    ("oc_passageway", "rrtconnect", 0): ("exact", 69, 16, 250.8072094589308),
    ("oc_passageway", "rrtconnect", 1): ("exact", 38, 3, 49.21856941295297),
}


def _check(res, golden):
    status, nodes, n_path, total = golden
    assert res.status.value == status and res.stats["nodes"] == nodes
    if n_path is not None:
        assert len(res.path) == n_path
        assert float(np.abs(res.path).sum()) == pytest.approx(total, rel=1e-9)


@pytest.mark.parametrize("variant,seed", sorted(GOLDEN_TCB))
def test_tcbirrt_unchanged_on_fixed_seeds(tcb, variant, seed):
    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.planners import TCBiRRT, TCBiRRTOptions, ValidityChecker
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    sc = Scene.load("ssps_scene1")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    # recorded before the improved variant took its orientations from the lead path (lead_orientation_probability)
    # and before its regrasp motions balanced their trees (regrasp_balance)
    from optplan.planners import RRTConnectOptions

    # extension="python" (and "native", the same search) is the golden reference: "loop" draws from its own stream
    o = TCBiRRTOptions(variant=variant, max_iterations=300, lead_orientation_probability=0.0, regrasp_balance=0.0,
                       regrasp=RRTConnectOptions(**PY_REGRASP), extension="python")
    pl = TCBiRRT(tcb, sc, o,
                 checker=ValidityChecker(tcb, sc), kinematics=ClosedChainKinematics(tcb, sc.object.grasps))
    _check(pl.plan(tr.q_start, tr.q_goal, time_limit=100, seed=seed), GOLDEN_TCB[(variant, seed)])


def test_tcbirrt_improved_defaults_unchanged_on_a_fixed_seed(tcb):
    """The improved variant's own defaults (lead-path orientations included), recorded 2026-11-24; the same search
    with the regrasp motions' tree balancing (the default since 2026-11-30): the same nodes, other regrasp motions."""
    from optplan.planners import TCBiRRT, TCBiRRTOptions
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    sc = Scene.load("ssps_scene1")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    from optplan.planners import RRTConnectOptions

    for balance, golden in ((0.0, ("exact", 114, 82, 1904.9856439901168)),   # recorded 2026-11-24
                            (None, ("exact", 114, 82, 1906.3002102344522))):  # the default 1 since 2026-11-30
        pl = TCBiRRT(tcb, sc, TCBiRRTOptions(variant="improved", max_iterations=1000, regrasp_balance=balance,
                                             regrasp=RRTConnectOptions(**PY_REGRASP), extension="python"))
        _check(pl.plan(tr.q_start, tr.q_goal, time_limit=100, seed=0), golden)


@pytest.mark.parametrize("scene_name,planner,seed", sorted(GOLDEN_PR2))
def test_pr2_planners_unchanged_on_fixed_seeds(scene_name, planner, seed):
    from optplan.model.example_robots import example_robots_available

    if not example_robots_available():
        pytest.skip("example-robot-data not installed (pip install 'optplan[robots]')")
    from optplan.bench.oc_rrt import setup_scene
    from optplan.planners import RRTConnect, RRTConnectOptions
    from optplan.planners.cbirrt2 import CBiRRT2
    from optplan.planners.oc_rrt import OCRRT, OCRRTOptions

    s = setup_scene(scene_name, ("oc_rrt",))
    if planner == "rrtconnect":
        # the trees alternating, as recorded (balancing is the default since 2026-11-30)
        pl = RRTConnect(s["robot"], s["scene"], RRTConnectOptions(max_iterations=2000, shortcut_iterations=20,
                                                                  range=0.3, native_search=False, balance=0.0),
                        checker=s["checker"])
    elif planner == "cbirrt":
        from optplan.planners.cbirrt2 import CBiRRT2Options

        pl = CBiRRT2(s["robot"], s["scene"], CBiRRT2Options(max_iterations=150), checker=s["checker"],
                     constraint=s["constraint"])
    else:
        before = dict(refine_depth=0, goal_region_bias=0.0, max_iterations=600,   # the options of then
                      certified_edges=False)
        o = OCRRTOptions(connect=True, **before) if planner == "oc_rrt_connect" else \
            OCRRTOptions(connect=False, goal_from_new=True, **before)
        pl = OCRRT(s["robot"], s["scene"], s["constraint"], o, checker=s["checker"], manifold=s["manifold"])
    _check(pl.plan(s["q_start"], s["q_goal"], time_limit=100, seed=seed), GOLDEN_PR2[(scene_name, planner, seed)])
