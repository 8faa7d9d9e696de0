"""The native calls' reused buffers and remembered array addresses (TCBiRRT's per-iteration glue): the
addresses are those of the arrays passed, also after a tree grows or kills nodes between calls; an extension
that reuses its output arrays gives what fresh arrays give, and never overwrites what an earlier call returned."""
from __future__ import annotations

import numpy as np
import pytest

from optplan.planners.kernel.addresses import AddressCache
from optplan.planners.kernel.extend import nearest_available


def test_address_cache_follows_the_arrays():
    cache = AddressCache(size=2)
    a, b, c = np.zeros((4, 6)), np.zeros(5, bool), np.ones(3)
    assert cache(None) is None
    for x in (a, b, a, c, b, a):        # more arrays than the cache holds: it forgets and looks up again
        assert cache(x) == x.ctypes.data
        assert len(cache) <= 2
    g = np.concatenate([a, a])          # a grown array is another object, with its own address
    assert cache(g) == g.ctypes.data != a.ctypes.data
    with pytest.raises(ValueError, match="size must be at least 1, got 0"):
        AddressCache(0)


@pytest.mark.skipif(not nearest_available(), reason="no C compiler: the native sampler is not built")
def test_sample_near_while_the_trees_grow_and_lose_nodes(tcb):
    """``sample_near`` between tree growths (new key arrays) and kills (new masks): its node is the live row
    nearest the sample by a numpy scan of the tree's keys."""
    from optplan.planners.kernel.extend import nearest
    from optplan.planners.kernel.sampler import NativeRandom, NativeTaskSampler
    from optplan.planners.tcbirrt_options import TCBiRRTOptions, reach_scaled_workspace
    from optplan.planners.tree import Tree

    lo, hi, _ = reach_scaled_workspace(tcb, TCBiRRTOptions())
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    rng = np.random.default_rng(11)
    mine, other = Tree(rng.uniform(lo, hi), cap=2), Tree(rng.uniform(lo, hi), cap=2)
    s = NativeTaskSampler(None, lo, hi, NativeRandom(4), goal_bias=0.3)
    grown = 0
    for it in range(300):
        X0 = mine.X
        mine.add(rng.uniform(lo, hi), int(rng.integers(mine.n)))
        other.add(rng.uniform(lo, hi), int(rng.integers(other.n)))
        grown += mine.X is not X0
        if it % 37 == 36:
            mine.kill(int(rng.integers(1, mine.n)))
        alive = mine.alive if mine.n_dead else None
        xi, i = s.sample_near(mine.X, mine.n, alive, other.X, other.n, other.alive if other.n_dead else None)
        d2 = np.sum((mine.X[:mine.n] - xi) ** 2, axis=1)
        if alive is not None:
            d2[~alive[:mine.n]] = np.inf
        assert i == int(np.argmin(d2))
        assert nearest(mine.X, mine.n, xi, alive) == i
    assert grown >= 7 and mine.n_dead > 0


def test_extensions_with_reused_arrays_are_those_with_fresh_ones(tcb):
    """60 native-loop extensions, the trapped ones' output arrays reused, against the same extensions with
    new arrays at every call (the stream reseeded): the same configurations, poses and counters; what a
    call returned is unchanged after the later calls."""
    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.planners import TCBiRRT, TCBiRRTOptions, ValidityChecker
    from optplan.planners.task_space import pose_from_xi, xi_from_pose
    from optplan.planners.tcbirrt_native import loop_extend
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    sc = Scene.load("hard_window")
    ck = ValidityChecker(tcb, sc)
    kin = ClosedChainKinematics(tcb, sc.object.grasps)
    pl = TCBiRRT(tcb, sc, TCBiRRTOptions(variant="improved", extension="loop"), checker=ck, kinematics=kin)
    pl._rng = np.random.default_rng(1)
    pl._sampler()
    if pl._nrng is None or pl._ext is None:
        pytest.skip("the native loop is not available here")
    ext = pl._ext
    q0 = TrialGenerator(tcb, sc).generate(0, 0).q_start
    M = kin.object_pose(q0)
    runs = {}
    for reuse in (True, False):
        pl._nrng.lib.tcb_rng_seed(pl._nrng.address, 5)
        r = np.random.default_rng(2)
        out, held = [], []
        for _ in range(60):
            Rs, ps = pose_from_xi(xi_from_pose(M) + r.normal(0.0, 1.0, 6) * np.r_[[0.15] * 3, [0.3] * 3])
            st = {k: 0 for k in ("ik_calls", "ik_iterations", "ik_restarts", "ik_failures", "ik_jumps", "collisions",
                                 "edge_checks", "edge_collisions")}
            if not reuse:
                ext._out = None
            poses, Q = loop_extend(pl, M.rotation, M.translation, Rs, ps, q0, st, True)
            snap = (None if Q is None else [q.copy() for q in Q], [(R.copy(), p.copy()) for R, p in poses])
            out.append((snap, st))
            held.append((Q, poses))
        for (Qs, Ps), (Q, poses) in zip((o[0] for o in out), held):   # nothing returned was overwritten
            assert (Q is None) == (Qs is None)
            if Q is not None:
                assert all(np.array_equal(a, b) for a, b in zip(Q, Qs))
            assert all(np.array_equal(R, Rc) and np.array_equal(p, pc) for (R, p), (Rc, pc) in zip(poses, Ps))
        runs[reuse] = out
    n_kept = 0
    for ((Qa, Pa), sa), ((Qb, Pb), sb) in zip(runs[True], runs[False]):
        assert sa == sb and (Qa is None) == (Qb is None)
        if Qa is not None:
            assert len(Qa) == len(Qb) and all(np.array_equal(a, b) for a, b in zip(Qa, Qb))
            n_kept += len(Qa) > 0
        assert len(Pa) == len(Pb) and all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
                                          for a, b in zip(Pa, Pb))
    assert 0 < n_kept < 60          # both kinds of extension ran: some kept configurations, some trapped
