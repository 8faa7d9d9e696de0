"""The planners' validity checks through Pinocchio's batch collision API against the reference: the
same checker with ``batch=False`` (one ``computeCollisions`` call on a broad-phase manager per
configuration, the implementation the batch path replaces). Same verdicts, same first collision of
a batch, same check counts, on random configurations of a cluttered scene."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.bench.hardscenes import nominal_configurations
from optplan.constraints.closed_chain import ClosedChainKinematics
from optplan.planners.rrtconnect import edge_is_valid
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene


@pytest.fixture(scope="module")
def setup(tcb):
    scene = Scene.load("hard_clutter_dense")
    fast = ValidityChecker(tcb, scene)
    ref = ValidityChecker(tcb, scene, batch=False)
    if not fast._pool:
        pytest.skip("this Pinocchio has no batch collision API (parallel module)")
    qs, qg = nominal_configurations(tcb, scene)
    return tcb, scene, fast, ref, qs, qg


def _configs(robot, q0, rng, n, sigma):
    return np.clip(q0 + rng.normal(0.0, sigma, (n, q0.size)), robot.lower, robot.upper)


def test_single_queries_match_reference(setup):
    robot, scene, fast, ref, qs, qg = setup
    rng = np.random.default_rng(3)
    Q = np.vstack([_configs(robot, qs, rng, 150, 0.3), _configs(robot, qg, rng, 150, 0.3)])
    M = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), np.array([0.05, -0.02, 0.04]))
    M_start = ClosedChainKinematics(robot, scene.object.grasps).object_pose(qs)
    held = [fast.is_valid(q) for q in Q]
    assert held == [ref.is_valid(q) for q in Q]
    assert 0.1 < np.mean(held) < 0.9          # both verdicts occur
    free = [fast.is_valid_free(q) for q in Q]
    assert free == [ref.is_valid_free(q) for q in Q]
    for pose in (M_start, M_start * M):       # the still object's pose changes between queries
        fixed = [fast.is_valid_object_fixed(q, pose) for q in Q]
        assert fixed == [ref.is_valid_object_fixed(q, pose) for q in Q]
        assert 0.05 < np.mean(fixed) < 0.95
    assert fast.n_checks == ref.n_checks


@pytest.mark.parametrize("mode", ["held", "fixed", "free"])
def test_first_invalid_matches_reference_loop(setup, mode):
    robot, scene, fast, ref, qs, qg = setup
    M = ClosedChainKinematics(robot, scene.object.grasps).object_pose(qs) if mode == "fixed" else None
    rng = np.random.default_rng(5)
    one = {"held": ref.is_valid, "free": ref.is_valid_free,
           "fixed": lambda q: ref.is_valid_object_fixed(q, M)}[mode]
    hits = 0
    for _ in range(60):
        Q = _configs(robot, qs, rng, int(rng.integers(1, 12)), float(rng.choice([0.02, 0.1, 0.4])))
        expect = next((k for k, q in enumerate(Q) if not one(q)), -1)
        n0 = fast.n_checks
        assert fast.first_invalid(Q, mode, M) == expect
        assert fast.n_checks - n0 == (len(Q) if expect < 0 else expect + 1)   # as many checks as the loop
        hits += expect >= 0
    assert 5 < hits < 55
    assert fast.first_invalid(np.zeros((0, robot.nq)), mode, M) == -1


def test_edges_match_reference(setup):
    """Edge checks (joint-space resolution, sweep weights, one arm moving with the object still, and the
    checker's own Jacobian-spaced edges): same verdicts and check counts as the reference."""
    robot, scene, fast, ref, qs, qg = setup
    kin = ClosedChainKinematics(robot, scene.object.grasps)
    M = kin.object_pose(qs)
    idx = kin.idx[1]
    W = fast.sweep_weights("held", per_geometry=True)
    rng = np.random.default_rng(11)
    verdicts = []
    for _ in range(40):
        a = _configs(robot, qs, rng, 1, 0.05)[0]
        b = _configs(robot, qs, rng, 1, 0.4)[0]
        n0, r0 = fast.n_checks, ref.n_checks
        v = edge_is_valid(a, b, fast.validity("held"), 0.05, check_end=False)
        assert v == edge_is_valid(a, b, ref.is_valid, 0.05, check_end=False)
        assert edge_is_valid(a, b, fast.validity("held"), 0.01, False, W) == edge_is_valid(a, b, ref.is_valid, 0.01, False, W)
        assert fast.edge_is_valid(a, b, 0.01, "held") == ref.edge_is_valid(a, b, 0.01, "held")
        assert fast.edge_is_valid(a, b, 0.01, "fixed", object_pose=M) == ref.edge_is_valid(a, b, 0.01, "fixed", object_pose=M)
        # one arm moving, the rest at a base configuration, the object still (a regrasp's edges)
        x, y = a[idx], b[idx]

        def arm_ref(z):
            q = qs.copy()
            q[idx] = z
            return ref.is_valid_object_fixed(q, M)

        arm = fast.validity("fixed", M, base=qs, joints=idx)
        assert edge_is_valid(x, y, arm, 0.03) == edge_is_valid(x, y, arm_ref, 0.03)
        assert arm(y) == arm_ref(y)
        assert fast.n_checks - n0 == ref.n_checks - r0
        verdicts.append(v)
    assert 0 < sum(verdicts) < len(verdicts)


def test_validity_bad_input(setup):
    robot, scene, fast, ref, qs, qg = setup
    with pytest.raises(ValueError, match="mode"):
        fast.validity("flying")
    with pytest.raises(ValueError, match="object_pose"):
        fast.validity("fixed")
    with pytest.raises(ValueError, match="base"):
        fast.validity("held", base=qs)
    with pytest.raises(ValueError, match="shape"):
        fast.first_invalid(qs, "held")
    with pytest.raises(ValueError, match="object_pose"):
        fast.first_invalid(qs[None, :], "fixed")


def _bisection_reference(n):
    """Coarse-to-fine interior points of 0..n, interval by interval (the former implementation)."""
    out, seen, queue = [], {0, n}, [(0, n)]
    while queue:
        nxt = []
        for lo, hi in queue:
            if hi - lo < 2:
                continue
            mid = (lo + hi) // 2
            if mid not in seen:
                seen.add(mid)
                out.append(mid)
            nxt += [(lo, mid), (mid, hi)]
        queue = nxt
    return out


def test_bisection_order_matches_reference():
    from optplan.planners.validity import _bisection_fractions, _bisection_indices, _bisection_order

    for n in [*range(0, 300), 511, 512, 513, 1000, 4097]:
        ref = _bisection_reference(n)
        assert _bisection_order(n) == ref
        assert sorted(ref) == list(range(1, n))                      # every interior point once
        if n >= 1:
            assert np.array_equal(_bisection_fractions(n), np.array([k / n for k in ref], dtype=float))
            assert np.array_equal(_bisection_indices(n), np.array(ref, dtype=int) - 1)


def test_without_batch_api_the_loop_answers_the_same(setup):
    """A checker with a security margin has no broad phase and no batch pool: ``first_invalid`` and the
    batch form of ``validity`` fall back to one query per row, with the same answers."""
    robot, scene, fast, ref, qs, qg = setup
    from optplan.planners.validity import ValidityChecker

    ck = ValidityChecker(robot, scene, margin=0.01)
    assert not ck._pool
    rng = np.random.default_rng(9)
    for _ in range(20):
        Q = _configs(robot, qs, rng, 6, 0.3)
        expect = next((k for k, q in enumerate(Q) if not ck.is_valid(q)), -1)
        assert ck.first_invalid(Q, "held") == expect
        assert ck.validity("held").first_invalid(Q) == expect


def test_exempted_pairs_skipped_by_batch_queries_too(setup):
    """``exempt`` (a regrasp's grasp contacts) switches pairs off for the single AND the batch queries, and
    back on after the block."""
    robot, scene, fast, ref, qs, qg = setup
    M = ClosedChainKinematics(robot, scene.object.grasps).object_pose(qs)
    rng = np.random.default_rng(21)
    Q = _configs(robot, qs, rng, 400, 0.5)
    q = next(x for x in Q if not ref.is_valid_object_fixed(x, M) and ref.colliding_pairs(x, "fixed", M))
    gd = ref._gd["fixed"]
    ref.colliding_pairs(q, "fixed", M)            # leaves the pairs' results in gd
    pairs = tuple(k for k in range(len(gd.collisionResults))
                  if gd.activeCollisionPairs[k] and gd.collisionResults[k].isCollision())
    with fast.exempt(pairs), ref.exempt(pairs):
        assert fast.is_valid_object_fixed(q, M) and ref.is_valid_object_fixed(q, M)
        assert fast.first_invalid(q[None, :], "fixed", M) == -1
        assert fast.validity("fixed", M).first_invalid(np.vstack([q, q])) == -1
    assert not fast.is_valid_object_fixed(q, M)
    assert fast.first_invalid(q[None, :], "fixed", M) == 0
