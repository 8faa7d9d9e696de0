"""TCBiRRT's native extension step and nearest-neighbour scan (optplan.planners.kernel.extend) against
the Python code they replace: numpy's brute-force search, interpolate_task, the compiled IK called from
Python, and the validity checker's edge checks."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.planners.kernel.extend import nearest, nearest_available

pytestmark = pytest.mark.skipif(not nearest_available(), reason="no C compiler: the native extension is not built")


def _brute(X, n, x, alive=None):
    d = X[:n] - x
    d2 = np.einsum("ij,ij->i", d, d)
    if alive is not None:
        d2[~alive[:n]] = np.inf
    return int(np.argmin(d2))


def test_native_nearest_matches_brute_force_with_dead_nodes_and_ties():
    rng = np.random.default_rng(11)
    for dim in (3, 6, 14):
        X = rng.normal(size=(700, dim))
        X[400:450] = X[300:350]                 # exact duplicates: the first index wins, as argmin's
        alive = rng.random(700) > 0.3
        for _ in range(200):
            n = int(rng.integers(1, 701))
            x = X[int(rng.integers(n))] if rng.random() < 0.3 else rng.normal(size=dim)
            assert nearest(X, n, x) == _brute(X, n, x)
            if alive[:n].any():
                assert nearest(X, n, x, alive) == _brute(X, n, x, alive)


def test_kd_index_gives_the_scans_answers_as_rows_are_appended():
    """The k-d index (rows appended between queries, so that some queries meet a tail of rows the tree was not built
    over, dead rows, exact ties, monotone chains, keys on a coarse grid with many equal distances): the scan's answer
    at every query, the first index among equals."""
    from optplan.planners.kernel.extend import kd_index

    rng = np.random.default_rng(12)
    for trial in range(24):
        dim, cap = int(rng.integers(2, 9)), int(rng.integers(600, 4000))
        X, (K, kdn) = np.empty((cap, dim)), kd_index(cap, dim)
        grid = trial % 3 == 0
        alive = np.ones(cap, bool) if trial % 2 else None
        n = 0
        while n < cap:
            m = min(cap, n + int(rng.integers(1, 900)))
            X[n:m] = rng.integers(0, 4, size=(m - n, dim)) * 0.5 if grid else rng.normal(size=(m - n, dim))
            if trial % 4 == 1:
                X[n:m] = np.cumsum(np.abs(X[n:m]), axis=0)
            n = m
            if alive is not None:
                alive[:n] = rng.random(n) < 0.7
            for _ in range(15):
                x = rng.integers(0, 4, size=dim) * 0.5 if grid else rng.normal(size=dim) * (3 if rng.random() < 0.5 else 40)
                want = _brute(X, n, x, alive) if alive is None or alive[:n].any() else -1
                assert nearest(X, n, x, alive, (K, kdn)) == want, (trial, n)
        # the index was built over all rows but a tail of at most a sixteenth of them (scanned)
        assert cap < 512 or (kdn[0] <= cap and 16 * (cap - kdn[0]) <= kdn[0]), (kdn[0], cap)


def test_kd_index_stays_within_its_slots_for_every_dim():
    """The index's tree over all rows (its row order and its nodes' boxes) fits the rows x (2 + dim) slots it is given:
    slots past them (a guard region of the same array) are never written, from 1 to 8 coordinates."""
    from optplan.planners.kernel.extend import kd_index

    rng = np.random.default_rng(5)
    for dim in range(1, 9):
        for cap in (512, 700, 1500, 4099):
            X = rng.normal(size=(cap, dim))
            K, kdn = kd_index(cap + 64, dim)
            K[cap:] = 777
            x = rng.normal(size=dim)
            assert nearest(X, cap, x, None, (K[:cap], kdn)) == _brute(X, cap, x)
            assert kdn[0] == cap
            assert (K[cap:] == 777).all(), (dim, cap)


def test_a_tree_with_an_index_answers_as_the_scan_after_growing_and_killing():
    from optplan.planners.tcbirrt_tree import _TaskTree

    rng = np.random.default_rng(4)
    t = _TaskTree(np.zeros(3), rng.normal(size=6), np.eye(3), np.zeros(3), cap=16)
    assert t.kd is not None
    for _ in range(3000):   # grows its arrays (and the index) eight times
        t.add(np.zeros(3), rng.normal(size=6), np.eye(3), np.zeros(3), int(rng.integers(t.n)), [], [])
        if t.n % 700 == 0:
            t.kill(int(rng.integers(1, t.n)))
            for _ in range(30):
                x = rng.normal(size=6)
                assert t.nearest(x) == _brute(t.X, t.n, x, t.alive)
    assert t.kd[0].shape == (len(t.X), 8)


def test_native_nearest_bad_input():
    X = np.zeros((5, 6))
    with pytest.raises(ValueError, match="rows of 3 values"):
        nearest(X, 5, np.zeros(3))
    with pytest.raises(ValueError, match="n = 9"):
        nearest(X, 9, np.zeros(6))
    with pytest.raises(ValueError, match="C-contiguous float64"):
        nearest(np.zeros((5, 6), np.float32), 5, np.zeros(6))
    with pytest.raises(ValueError, match="k-d index of 5 x 8"):
        nearest(X, 5, np.zeros(6), None, (np.zeros((4, 2), np.int64), np.zeros(1, np.int64)))


def test_tree_uses_the_native_scan_with_the_same_answers():
    from optplan.planners.tree import Tree

    rng = np.random.default_rng(3)
    t = Tree(rng.normal(size=6), cap=4)
    for _ in range(300):
        t.add(rng.normal(size=6), int(rng.integers(t.n)))
    t.kill(57)
    for _ in range(100):
        x = rng.normal(size=6)
        assert t.nearest(x) == _brute(t.X, t.n, x, t.alive)


def _planners(robot, scene, **options):
    """A TCBiRRT with the native extension and one with the Python extension, sharing the checker and
    the kinematics."""
    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.planners import TCBiRRT, TCBiRRTOptions, ValidityChecker

    ck, kin = ValidityChecker(robot, scene), ClosedChainKinematics(robot, scene.object.grasps)
    nat = TCBiRRT(robot, scene, TCBiRRTOptions(extension="native", **options), checker=ck, kinematics=kin)
    py = TCBiRRT(robot, scene, TCBiRRTOptions(extension="python", **options), checker=ck, kinematics=kin)
    if nat._ext is None:
        pytest.skip("the native extension is not available here (kernel or IK not compiled)")
    assert py._ext is None
    return nat, py


def test_interpolation_matches_interpolate_task(tcb):
    from optplan.planners.task_space import interpolate_task
    from optplan.scene import Scene

    nat, _ = _planners(tcb, Scene.load("ssps_scene1"))
    rng = np.random.default_rng(5)
    for k in range(300):
        R0 = np.asarray(pin.exp3(rng.normal(size=3) * 2.0))
        w = rng.normal(size=3) * (1e-7 if k % 5 == 0 else 1.0)
        if k % 7 == 0:   # a relative half turn, less a hair: the log's branch near π
            w = np.pi * (1 - 1e-9) * w / np.linalg.norm(w)
        R1 = R0 @ np.asarray(pin.exp3(w))
        p0, p1 = rng.normal(size=3), rng.normal(size=3)
        P = nat._ext.interpolate(R0, p0, R1, p1, 5)
        for j, (R, p) in enumerate(interpolate_task(R0, p0, R1, p1, 5)):
            assert np.abs(P[j, :9] - R.ravel()).max() < 1e-9 and np.abs(P[j, 9:] - p).max() < 1e-12
        assert np.array_equal(P[-1, :9], R1.ravel()) and np.array_equal(P[-1, 9:], p1)


@pytest.mark.parametrize("variant,extra", [("improved", {}), ("paper", {}), ("improved", {"edge_resolution": 0.05}),
                                           ("improved", {"ik_predictor": "secant"}),
                                           ("paper", {"ik_predictor": "secant", "edge_resolution": 0.05})])
def test_one_extension_matches_the_python_one(tcb, variant, extra):
    """Random extensions from valid configurations of hard_bay: the same accepted configurations (to
    rounding), the same counters and the same draws from the generator (restarts) as the Python code."""
    from optplan.planners.task_space import interpolate_task, pose_from_xi, xi_from_pose
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    sc = Scene.load("hard_bay")
    nat, py = _planners(tcb, sc, variant=variant, **extra)
    rng = np.random.default_rng(8)
    kinds = set()
    for t in range(4):
        tr = TrialGenerator(tcb, sc).generate(t, 0)
        for q0 in (tr.q_start, tr.q_goal):
            M = nat.kin.object_pose(q0)
            xi0 = xi_from_pose(M)
            for _ in range(25):
                xi = xi0 + rng.normal(0.0, 1.0, 6) * np.r_[[0.15] * 3, [0.3] * 3]
                Rs, ps = pose_from_xi(xi)
                out = []
                for pl in (nat, py):
                    pl._rng = np.random.default_rng(1)
                    st = {k: 0 for k in ("ik_calls", "ik_iterations", "ik_restarts", "ik_failures", "ik_jumps",
                                         "collisions", "edge_checks", "edge_collisions")}
                    n0 = pl.checker.n_checks
                    if pl is nat:
                        from optplan.planners.tcbirrt_native import native_extend

                        _, Q = native_extend(pl, M.rotation, M.translation, Rs, ps, q0, st, bool(pl.options.keep_prefix))
                    else:
                        poses = interpolate_task(M.rotation, M.translation, Rs, ps, pl.options.n_interp)
                        Q = pl.path_ik(poses, q0, st, prefix=bool(pl.options.keep_prefix))
                    out.append((None if Q is None else np.array(Q), st, pl.checker.n_checks - n0, pl._rng.random()))
                (Qn, stn, cn, rn), (Qp, stp, cp, rp) = out
                assert stn == stp and cn == cp and rn == rp
                assert (Qn is None) == (Qp is None)
                if Qn is not None:
                    assert Qn.shape == Qp.shape and (Qn.size == 0 or np.abs(Qn - Qp).max() < 1e-9)
                kinds.add("none" if Qn is None else ("full" if len(Qn) == nat.options.n_interp else "prefix"))
                kinds.update(k for k in ("ik_restarts", "ik_failures", "collisions", "edge_collisions") if stn[k])
    assert {"full"} <= kinds and len(kinds) >= 3   # the cases the comparison covered


@pytest.mark.parametrize("variant,seed,extra", [("improved", 2, {}), ("paper", 1, {}),
                                                ("improved", 0, {"edge_resolution": 0.05}),
                                                ("improved", 2, {"ik_predictor": "secant"})])
def test_same_search_with_the_native_and_the_python_extension(tcb, variant, seed, extra):
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    sc = Scene.load("hard_bay")
    tr = TrialGenerator(tcb, sc).generate(1, 0)
    out = []
    for pl in _planners(tcb, sc, variant=variant, max_iterations=250, **extra):
        res = pl.plan(tr.q_start, tr.q_goal, time_limit=100, seed=seed)
        s = res.stats
        out.append((res.status.value, s["iterations"], s["nodes"], s["ik_iterations"], s["collision_checks"],
                    None if res.path is None else len(res.path),
                    None if res.path is None else round(float(np.abs(res.path).sum()), 6)))
    assert out[0] == out[1]


def test_extension_option_is_checked():
    from optplan.planners import TCBiRRTOptions

    with pytest.raises(ValueError, match="extension: expected 'loop', 'native' or 'python', got 'c'"):
        TCBiRRTOptions(extension="c")


@pytest.mark.parametrize("scene_name", ["hard_window", "hard_clutter_dense"])
def test_native_pose_filter_matches_the_python_filter(tcb, scene_name):
    """ObjectPoseFilter's ξ test, its bridge classes and its segment test in one native call against the
    same filter in Python (rotation from Pinocchio's RPY, reach in numpy, the kernel's object check)."""
    from optplan.planners.rrtconnect import edge_is_valid
    from optplan.planners.task_sampling import ObjectPoseFilter, _rpy_matrix
    from optplan.planners.tcbirrt_options import TCBiRRTOptions, reach_scaled_workspace
    from optplan.scene import Scene

    sc = Scene.load(scene_name)
    f = ObjectPoseFilter(tcb, sc)
    if f._xi_native is None:
        pytest.skip("no native filter here")
    lo, hi, _ = reach_scaled_workspace(tcb, TCBiRRTOptions())
    rng = np.random.default_rng(2)
    seen = set()
    for _ in range(3000):
        xi = rng.uniform(lo, hi)
        R = _rpy_matrix(xi)
        want = 0 if not f.reachable(R, xi[:3]) else (2 if f.object_free(R, xi[:3]) else 1)
        assert f.xi_class(xi) == want
        assert f.xi_class(xi, reach=False) == (2 if f.object_free(R, xi[:3]) else 1)
        assert f.xi_ok(xi) == (want == 2)
        seen.add(want)
    assert seen == {0, 1, 2}
    both = set()
    for _ in range(300):
        a = rng.uniform(lo, hi)
        b = a + rng.normal(0.0, 0.3, 6)
        n0 = f.n_calls
        got = f.segment_ok(a, b, 0.04)
        n_native = f.n_calls - n0
        n0 = f.n_calls
        want = edge_is_valid(a, b, lambda x: f(_rpy_matrix(x), x[:3]), 0.04)
        assert got == want and n_native == f.n_calls - n0
        both.add(got)
    assert both == {True, False}


def test_bench_summary_and_python_nearest_context():
    from optplan.bench import tcbirrt_native as bn
    from optplan.planners import tree

    rows = [{"scene": "s", "trial": i, "kind": k, "status": "exact", "cpu_s": c, "iterations": it,
             "cpu_per_iteration_ms": 1e3 * c / it, "nodes": nd, "native": True}
            for i, (k, c, it, nd) in enumerate([("native", 0.1, 100, 10), ("python", 0.3, 100, 10),
                                                ("native", 0.2, 50, 5), ("python", 0.2, 60, 5)])]
    for r in rows:
        r["trial"] //= 2
    out = bn.summary(rows)
    assert "median 1.92x (min 0.83, max 3.00)" in out and "same iterations/nodes in 1/2" in out
    tree._native_nearest()
    before = list(tree._NATIVE_NN)
    with bn.python_nearest():
        assert tree._NATIVE_NN == [None]
    assert tree._NATIVE_NN == before and tree._NATIVE_NN[0] is not None

