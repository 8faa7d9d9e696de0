"""TCBiRRT's trapped streaks (optplan.planners.tcbirrt_streak) and the native loop's other shortcuts: each
gives the search it replaces, iteration for iteration. Checked against the loop without them on fixed seeds,
against Pinocchio (the target pose, the hands' placements) and against the compiled IK block called from
Python."""
from __future__ import annotations

import dataclasses
import platform

import numpy as np
import pinocchio as pin
import pytest

from optplan.planners.kernel.extend import nearest_available

pytestmark = pytest.mark.skipif(not nearest_available(), reason="no C compiler: the native loop is not built")


def _planner(robot, scene_name, **options):
    from optplan.planners.tcbirrt import TCBiRRT
    from optplan.planners.tcbirrt_options import TCBiRRTOptions
    from optplan.scene import Scene

    pl = TCBiRRT(robot, Scene.load(scene_name), TCBiRRTOptions(variant="improved", **options))
    if pl._ext is None:
        pytest.skip("no native extension here")
    return pl


def _same(a, b) -> bool:
    return (a.status == b.status and a.stats["iterations"] == b.stats["iterations"] and a.stats["nodes"] == b.stats["nodes"]
            and len(a.path) == len(b.path) and all(np.array_equal(x, y) for x, y in zip(a.path, b.path)))


@pytest.mark.parametrize("scene_name, trials, options", [
    ("hard_bay", (3, 4), {}), ("hard_clutter_dense", (3,), {}), ("hard_window", (5,), {}),
    # the adaptive step (halved in C when trapped) and a stall bound on the streaks
    ("hard_bay", (5,), {"trap_adapt": "step", "stall_iterations": 120}),
    # the dynamic domain (its draws and its trapped nodes' domains in C)
    ("hard_bay", (3, 6), {"trap_adapt": "domain", "domain_radius": 2.0}),
    # extensions that keep no prefix (a failed one is trapped whole)
    ("ssps_scene2", (0, 1, 2), {"keep_prefix": False})])
def test_streaks_and_restart_skips_give_the_same_search(tcb, scene_name, trials, options):
    """Streaks on/off and the skipped restarts on/off: the same iterations, nodes and path, bit for bit (the streaks
    ran: several iterations per call on these trapped scenes; restarts were skipped)."""
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    on = _planner(tcb, scene_name, **options)
    off = _planner(tcb, scene_name, streaks=False, **options)
    plain = _planner(tcb, scene_name, streaks=False, **options)
    plain._ext._ctx.pfix = None          # every restart run
    plain._ext._ctx.npfl = 0             # and every waypoint's IK (no pose test before it)
    gen = TrialGenerator(tcb, Scene.load(scene_name))
    skipped = 0
    for t in trials:
        tr = gen.generate(t, 0)
        ra, rb, rc = (p.plan(tr.q_start, tr.q_goal, time_limit=30.0, seed=t, clock="cpu") for p in (on, off, plain))
        assert ra.status.value == "exact"
        assert _same(ra, rb) and _same(ra, rc), (scene_name, t, ra.stats["iterations"], rb.stats["iterations"],
                                                 rc.stats["iterations"])
        assert ra.stats["trapped"] == rb.stats["trapped"] == rc.stats["trapped"]
        skipped += ra.stats.get("ik_restarts_skipped", 0)
        assert rc.stats.get("ik_restarts_skipped", 0) == 0 and rc.stats.get("pose_blocked", 0) == 0
        assert ra.stats.get("pose_blocked", 0) > 0
        assert ra.stats["ik_iterations"] <= rc.stats["ik_iterations"]
    assert skipped > 0


def _check_trees(trees, robot, log=None):
    """Every node of the trees (and every configuration of its edge) within the joint limits, its parent before it,
    the lists as long as the arrays; ``log``: the node log rows a call wrote (tree, node, configurations kept)."""
    lo, hi = robot.lower - 1e-6, robot.upper + 1e-6
    for t in trees:
        n = t.n
        assert len(t.pose) == len(t.edge) == n and np.isfinite(t.X[:n]).all()
        assert np.all((t.q[:n] >= lo) & (t.q[:n] <= hi))
        assert np.all((t.parent[1:n] >= 0) & (t.parent[1:n] < np.arange(1, n)))
        for eq, ep in t.edge[:n]:
            assert len(ep) == len(eq) and all(np.all((x >= lo) & (x <= hi)) for x in eq)
    if log is not None:
        assert np.all(log[:, 2] >= 1)


@pytest.mark.parametrize("scene_name, trial, options", [("hard_bay", 3, {}), ("ssps_scene2", 1, {"keep_prefix": False})])
def test_the_nodes_a_streak_adds_are_whole(tcb, scene_name, trial, options):
    """After every native call (streak or connection) the trees are whole: their nodes and edges' configurations
    within the joint limits, parents before children, the Python lists as long as the arrays, the log's rows kept
    configurations (an extension trapped without a prefix is not a node)."""
    from optplan.planners import tcbirrt_streak as ts
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    pl = _planner(tcb, scene_name, **options)
    run, conn = ts.NativeStreak.run, ts.NativeStreak.connect
    calls = []

    def spy_run(self, ta, tb, *a, **k):
        out = run(self, ta, tb, *a, **k)
        _check_trees((ta, tb), tcb, self.LM[:out.n_log])
        calls.append(int(out.n_log))
        return out

    def spy_conn(self, tb, *a, **k):
        out = conn(self, tb, *a, **k)
        _check_trees((tb,), tcb, self.LM[:out.n_log])
        calls.append(int(out.n_log))
        return out
    ts.NativeStreak.run, ts.NativeStreak.connect = spy_run, spy_conn
    try:
        tr = TrialGenerator(tcb, Scene.load(scene_name)).generate(trial, 0)
        r = pl.plan(tr.q_start, tr.q_goal, time_limit=30.0, seed=trial, clock="cpu")
    finally:
        ts.NativeStreak.run, ts.NativeStreak.connect = run, conn
    assert r.status.value == "exact" and sum(calls) > 0   # nodes were added in C


def test_a_streak_runs_several_iterations_and_stops_where_python_must_go_on(tcb):
    """On a trapped scene the calls average more than one iteration; each ends at one of its codes; the trees' Python
    lists hold every node the calls added."""
    from optplan.planners import tcbirrt_streak as ts
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    pl = _planner(tcb, "hard_bay")
    seen: list[tuple[int, int]] = []
    run = ts.NativeStreak.run

    def spy(self, *a, **k):
        out = run(self, *a, **k)
        seen.append((int(out.code), int(out.n_done)))
        for t in a[:2]:   # the nodes added in C: in the arrays and in the lists of poses and edges
            assert len(t.pose) == len(t.edge) == t.n and np.isfinite(t.X[:t.n]).all()
        return out
    ts.NativeStreak.run = spy
    try:
        tr = TrialGenerator(tcb, Scene.load("hard_bay")).generate(3, 0)
        r = pl.plan(tr.q_start, tr.q_goal, time_limit=30.0, seed=3, clock="cpu")
    finally:
        ts.NativeStreak.run = run
    assert r.status.value == "exact" and seen
    codes = {c for c, _ in seen}
    assert codes <= {ts.STREAK_DONE, ts.STREAK_SAMPLED, ts.STREAK_EXTENDED, ts.STREAK_TRAP_GRAFT, ts.STREAK_CONNECT,
                     ts.STREAK_CONNECTED}
    # advanced extensions go on in C: the calls stop where a connection step was not trapped
    assert ts.STREAK_CONNECTED in codes
    done = sum(n for _, n in seen) + sum(c != ts.STREAK_DONE for c, _ in seen)
    assert done / len(seen) > 5.0            # iterations per call
    assert done <= r.stats["iterations"]


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="bit-equality assumes no fused multiply-adds")
def test_the_target_pose_is_pinocchios_to_the_bit():
    from optplan.planners.tcbirrt_streak import NativePose

    f, rng = NativePose(), np.random.default_rng(11)
    for _ in range(3000):
        xi = rng.uniform(-3.3, 3.3, 6)
        R, p = f(xi)
        assert np.array_equal(R, np.asarray(pin.rpy.rpyToMatrix(*xi[3:]))) and np.array_equal(p, xi[:3])
    R, _ = f(np.r_[0.0, 0.0, 0.0, 0.0, np.pi / 2, 0.0])    # gimbal lock still a rotation
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-15)


def test_ik_block_in_c_is_the_python_loop_to_the_bit(tcb):
    pl = _planner(tcb, "hard_bay")
    kin, rng = pl.kin, np.random.default_rng(4)
    conv = 0
    for _ in range(300):
        q = rng.uniform(tcb.lower, tcb.upper)
        M = kin.object_pose(q)
        seed = q + rng.normal(0.0, 0.1, q.size)
        a, ia = kin.ik(seed, M.rotation, M.translation, pl.options.ik)
        b, ib = pl._ext.ik_block(seed, M.rotation, M.translation)
        assert ia == ib and (a is None) == (b is None)
        if a is not None:
            conv += 1
            assert np.array_equal(a, b)
    assert conv > 20


def test_pose_fixed_pairs_are_placed_by_the_object_pose_alone(tcb):
    """Two IK solutions of one object pose (Pinocchio's forward kinematics): every joint that carries a geometry of a
    flagged pair is at the same placement; some unflagged pair has a geometry on a joint that moved."""
    from optplan.planners.kernel.extend import pose_fixed_pairs

    pl = _planner(tcb, "hard_bay")
    kern = pl.checker._native.kernel
    fix = pose_fixed_pairs(kern, pl.kin)
    gparent, pa, pb = kern._arrays[5], kern._arrays[10], kern._arrays[11]
    assert fix is not None and 0 < fix.sum() < fix.size
    model, data, rng = tcb.model, tcb.model.createData(), np.random.default_rng(9)
    pairs = 0
    for _ in range(200):
        q0 = rng.uniform(tcb.lower, tcb.upper)
        M = pl.kin.object_pose(q0)              # arm 1's hand holds the object here; both hands hold it at q1 and q2
        q1, _ = pl.kin.ik(q0, M.rotation, M.translation, pl.options.ik)
        if q1 is None:
            continue
        q2, _ = pl.kin.ik(q1 + rng.normal(0.0, 0.8, q1.size), M.rotation, M.translation, pl.options.ik)
        if q2 is None or np.abs(q2 - q1).max() < 0.3:
            continue
        pin.forwardKinematics(model, data, q1)
        o1 = [data.oMi[j].copy() for j in range(model.njoints)]
        pin.forwardKinematics(model, data, q2)
        o2 = [data.oMi[j].copy() for j in range(model.njoints)]
        same = [np.allclose(o1[j].homogeneous, o2[j].homogeneous, atol=1e-6) for j in range(model.njoints)]
        for k in np.flatnonzero(fix):
            assert same[int(gparent[pa[k]])] and same[int(gparent[pb[k]])]
        assert any(not (same[int(gparent[pa[k]])] and same[int(gparent[pb[k]])]) for k in np.flatnonzero(fix == 0))
        pairs += 1
        if pairs >= 10:
            break
    assert pairs >= 5


@pytest.mark.parametrize("scene_name", ["hard_bay", "hard_clutter_dense"])
def test_pose_test_before_the_ik_is_the_full_check_of_the_pose_fixed_pairs(tcb, scene_name):
    """The test of a waypoint's object pose alone (``tcb_pose_blocked``: the hands' joints put at the grasps, the
    flagged pairs' geometries placed from them) against the kernel's check of the same pairs at closed-chain
    configurations of that pose (forward kinematics through the arms): the same verdict wherever the pairs are not
    within 1e-6 m of contact, with poses blocked and free among them."""
    import ctypes

    from optplan.planners.kernel.extend import pose_fixed_pairs, pose_test_layout
    from optplan.planners.kernel.native import se3_pose12

    pl = _planner(tcb, scene_name)
    ext, kern = pl._ext, pl.checker._native.kernel
    fix = pose_fixed_pairs(kern, pl.kin)
    layout = pose_test_layout(kern, pl.kin, fix)
    assert layout is not None and ext._ctx.npfl == len(layout[0]) > 0
    active = np.asarray(pl.checker._native.masks["held"], np.uint8)
    mask = np.ascontiguousarray(fix & active, dtype=np.uint8)
    rng = np.random.default_rng(31)
    lo, hi = np.asarray(pl._lo), np.asarray(pl._hi)
    seen = {True: 0, False: 0}
    for _ in range(3000):
        q0 = rng.uniform(tcb.lower, tcb.upper)
        M = pl.kin.object_pose(q0)
        M.translation = rng.uniform(lo[:3], hi[:3])      # the object anywhere in the sampling box
        q1, _ = pl.kin.ik(q0, M.rotation, M.translation, pl.options.ik)
        if q1 is None:
            continue
        P = np.ascontiguousarray(se3_pose12(pl.kin.object_pose(q1)))
        slack = kern.pair_slacks(q1)[mask.astype(bool)]
        if np.any(np.abs(slack) < 1e-6):
            continue
        blocked = bool(ext.lib.tcb_pose_blocked_api(ctypes.c_void_p(ext._cp), P.ctypes.data))
        assert blocked == kern.collides(q1, mask), (q1, blocked)
        seen[blocked] += 1
        if min(seen.values()) >= 15 and sum(seen.values()) >= 60:
            break
    assert seen[True] >= 15 and seen[False] >= 15, seen


def test_quiet_iterations_stop_before_every_event_of_the_loops_head(tcb):
    """The closed form against the head's own tests, iteration by iteration (options with every event on)."""
    from optplan.planners.tcbirrt_streak import quiet_iterations

    pl = _planner(tcb, "hard_bay")
    o = dataclasses.replace(pl.options, branch_grafts=2, graft_after=40, graft_interval=30, frontier_grafts=3,
                            frontier_interval=45, stall_iterations=70, guide_probability=0.2)
    pl.options = o

    class _S:
        guide = None

    def fires(v: int, since: int, max_it: int) -> bool:   # the head of the iteration with v iterations before it
        k_graft, k_front = v - o.graft_after, v + 1 - o.graft_after
        return bool((max_it and v >= max_it) or (k_graft > 0 and k_graft % o.graft_interval == 0) or v % 25 == 0
                    or (k_front > 0 and k_front % o.frontier_interval == 0) or since > o.stall_iterations)
    for v0 in range(0, 400, 7):
        for since0 in (1, 30, 69, 70, 71):
            for max_it in (0, v0 + 3, v0 + 200):
                n = quiet_iterations(pl, v0, since0, max_it, _S(), True, True)
                expect = next(j for j in range(1, 10_000) if fires(v0 + j, since0 + j, max_it))
                assert n == expect, (v0, since0, max_it, n, expect)


def test_streaks_option_is_checked():
    from optplan.planners.tcbirrt_options import TCBiRRTOptions

    with pytest.raises(ValueError, match="streaks: expected True or False"):
        TCBiRRTOptions(streaks=1)


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="bit-equality assumes no fused multiply-adds")
def test_a_partial_nodes_key_is_pinocchios_to_the_bit():
    """The native ξ of a pose (``tcb_xi_of_pose``) against Pinocchio's matrixToRpy: random rotations, and rotations
    near the pitch's singularity (±π/2) and the angles' branch cuts (±π)."""
    from optplan.planners.task_space import xi_from_pose
    from optplan.planners.tcbirrt_streak import NativeXi

    f, rng = NativeXi(), np.random.default_rng(12)
    eps = np.concatenate([[0.0], 10.0 ** -np.arange(1, 16)])
    for k in range(6000):
        if k % 3 == 0:
            R = pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
        elif k % 3 == 1:
            R = pin.exp3(rng.normal(size=3) * rng.choice([1e-9, 1e-3, 1.0, 3.0]))
        else:   # pitch at ±π/2 and angles at ±π, up to a tiny offset
            r, y = rng.choice([-np.pi, np.pi, 0.0, np.pi / 2]) + rng.choice(eps) * rng.choice([-1, 1], 2)
            pch = rng.choice([-np.pi / 2, np.pi / 2]) + rng.choice(eps) * rng.choice([-1, 1])
            R = pin.rpy.rpyToMatrix(r, pch, y)
        p = rng.normal(size=3)
        a, b = f(R, p), xi_from_pose(pin.SE3(R, p))
        assert np.array_equal(a, b), (R, a, b)


def test_native_twin_choice_is_the_trees_on_groups_with_dead_nodes():
    """Twin groups grown by ``add_graft`` (grafts at any member, dead members): the arrays list each group in the
    order of ``twins``, and the native choice of the twin nearest a configuration is the tree's."""
    from optplan.planners.tcbirrt_streak import NativeTwin
    from optplan.planners.tcbirrt_tree import _TaskTree

    rng = np.random.default_rng(5)
    nq = 14
    t = _TaskTree(rng.normal(size=nq), rng.normal(size=6), np.eye(3), np.zeros(3), cap=4)
    for _ in range(60):   # plain nodes, then grafts at random nodes (a member of a group or not)
        t.add(rng.normal(size=nq), rng.normal(size=6), np.eye(3), np.zeros(3), int(rng.integers(t.n)), [], [])
    for _ in range(80):
        t.add_graft(int(rng.integers(t.n)), rng.normal(size=nq), [])
    for i in range(t.n):
        if i in t.twins:
            walk, m = [], int(t.thead[i])
            while m >= 0:
                walk.append(m)
                m = int(t.tnext[m])
            assert walk == t.twins[i]
        else:
            assert t.thead[i] == -1 and not t.twin[i]
    twin = NativeTwin()
    t.kill(int(rng.integers(1, t.n)))
    for _ in range(400):
        i = int(rng.integers(t.n))
        if t.alive is not None and not t.alive[i]:
            continue
        q = rng.normal(size=nq) if rng.random() < 0.7 else t.q[int(rng.integers(t.n))].copy()
        assert twin(t, i, q, rng) == t.twin_nearest(i, q, rng)


def test_native_twin_draws_are_numpys_generator_integers():
    """Generator.integers(n) on the PCG64 state, in C, against NumPy's own draws: the values and the state after
    them (the buffered 32-bit half included), for the group sizes twins have and larger ones."""
    import ctypes

    from optplan.planners.kernel.extend import load_extend_library
    from optplan.planners.tcbirrt_streak import _declare, _Pcg

    lib = load_extend_library()
    _declare(lib)
    for seed in range(40):
        g, ref = np.random.default_rng(seed), np.random.default_rng(seed)
        if seed % 2:   # leave a buffered 32-bit half
            g.integers(5), ref.integers(5)
        for n in (1, 2, 3, 5, 7, 12, 1000, 2**31 + 11):
            pcg = _Pcg()
            assert pcg.load(g)
            out = np.zeros(25, np.int64)
            if lib.tcb_pcg_integers(ctypes.byref(pcg), n, len(out), out.ctypes.data) < 0:
                pytest.skip("no 128-bit integers in this C compiler")
            pcg.store(g)
            assert out.tolist() == [int(ref.integers(n)) for _ in range(len(out))], (seed, n)
            assert g.bit_generator.state == ref.bit_generator.state


def test_native_seed_draws_are_numpys_generator_uniform():
    """Generator.uniform(lower, upper) on the PCG64 state, in C (the look-ahead grafts' IK seeds), against NumPy's own
    draws: the values to the bit and the state after them (a buffered 32-bit half left untouched)."""
    import ctypes

    from optplan.planners.kernel.extend import load_extend_library
    from optplan.planners.tcbirrt_streak import _Pcg

    lib = load_extend_library()
    lib.tcb_pcg_uniform.restype = ctypes.c_int
    lib.tcb_pcg_uniform.argtypes = [ctypes.c_void_p] * 3 + [ctypes.c_int, ctypes.c_void_p]
    lo = np.array([-3.1, -2.0, 0.0, -1e-3, -7.5, 2.0, -np.pi])
    hi = np.array([3.1, 2.5, 1.0, 1e-3, 0.5, 2.0 + 1e-12, np.pi])
    rng = np.subtract(hi, lo)
    for seed in range(30):
        g, ref = np.random.default_rng(seed), np.random.default_rng(seed)
        if seed % 2:   # leave a buffered 32-bit half
            g.integers(5), ref.integers(5)
        for _ in range(5):
            pcg, out = _Pcg(), np.empty(lo.size)
            assert pcg.load(g)
            if lib.tcb_pcg_uniform(ctypes.byref(pcg), lo.ctypes.data, rng.ctypes.data, lo.size, out.ctypes.data) < 0:
                pytest.skip("no 128-bit integers in this C compiler")
            pcg.store(g)
            assert np.array_equal(out, ref.uniform(lo, hi)), seed
            assert g.bit_generator.state == ref.bit_generator.state


@pytest.mark.parametrize("scene_name, trials", [("hard_bay", (3, 4, 5)), ("hard_truss", (0, 7)), ("hard_clutter_dense", (3,))])
def test_native_lookahead_gives_the_same_search(tcb, scene_name, trials, monkeypatch):
    """The look-ahead grafts' candidate loop in C (NativeLookahead) and in Python: the same iterations, nodes, path
    (bit for bit) and graft counters, on queries where look-ahead grafts were tried and some were made."""
    from optplan.planners import tcbirrt_sampling
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    on = _planner(tcb, scene_name)
    off = _planner(tcb, scene_name)
    native = tcbirrt_sampling.SamplingMixin._native_sampler

    def without(self):   # the native loop, its look-ahead candidates in Python
        smp = native(self)
        if self is off:
            self._la = None
        return smp
    monkeypatch.setattr(tcbirrt_sampling.SamplingMixin, "_native_sampler", without)
    gen = TrialGenerator(tcb, Scene.load(scene_name))
    tried = made = 0
    for t in trials:
        tr = gen.generate(t, 0)
        ra, rb = (p.plan(tr.q_start, tr.q_goal, time_limit=30.0, seed=t, clock="cpu") for p in (on, off))
        assert ra.status.value == "exact"
        assert _same(ra, rb), (scene_name, t, ra.stats["iterations"], rb.stats["iterations"])
        for k in ("trap", "frontier"):
            for c in ("attempts", "grafts", "lookahead_failures", "regrasp_failures"):
                assert ra.stats.get(f"{k}_{c}", 0) == rb.stats.get(f"{k}_{c}", 0), (t, k, c)
            tried += ra.stats.get(f"{k}_attempts", 0)
            made += ra.stats.get(f"{k}_grafts", 0)
        assert ra.stats["ik_iterations"] == rb.stats["ik_iterations"]
    assert on._la is not None and tried > 0 and made > 0, (tried, made)
