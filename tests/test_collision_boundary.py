"""CollisionAvoidance next to fixed joints and fixed boundary configurations.

* Pairs with no free joint (a JointPositionLimits holds some joints at lower == upper) are left
  out: checked against an independent criterion — the pair's coal distance does not change when
  every free joint is randomised.
* Rows within ``window`` knots of a pinned boundary configuration that is closer than ``margin``
  get ``min(margin, d/2)`` (d: coal's distance at the boundary) and the NLP stays solvable; the
  rest keep ``margin``.
"""
from __future__ import annotations

import numpy as np
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.problem import (
    CollisionAvoidance,
    JointBoundary,
    JointPositionLimits,
    JointVelocityLimits,
    OptProblem,
    Smoothness,
)
from optplan.scene import Scene
from optplan.verification import verify


@pytest.fixture(scope="module")
def transport():
    return Scene.load("transport")


def test_pairs_without_free_joint_are_left_out(tcb, transport, rng):
    hold = tcb.arm("A").j_idx
    q0 = tcb.random_joints(rng) * 0.3
    lo, hi = tcb.lower.copy(), tcb.upper.copy()
    lo[hold] = hi[hold] = q0[hold]
    prob = OptProblem(tcb, n_intervals=3, duration=3.0)
    term = CollisionAvoidance(transport, margin=0.02, activation=1e6, object_arm="A")
    prob.add_constraint(term)
    prob.add_constraint(JointPositionLimits(lower=lo, upper=hi))
    Q = np.array([q0] * 4)
    Q[:, [i for i in range(tcb.nj) if i not in hold]] += rng.uniform(-0.3, 0.3, (4, tcb.nj - len(hold)))
    prob.set_initial(q=Q)
    info = prob.term_data(prob.terms["collision"]).info
    # independent: pairs whose exact distance is the same whatever the free joints do
    chk = CollisionChecker(tcb, transport, object_arm="A")
    free = [i for i in range(tcb.nj) if i not in hold]
    D = []
    for _ in range(6):
        q = q0.copy()
        q[free] = tcb.random_joints(rng)[free]
        D.append(chk.distances(q))
    D = np.array(D)
    constant = [p for i, p in enumerate(chk.pairs) if np.ptp(D[:, i]) < 1e-12]
    assert constant, "the test needs pairs with no free joint (holding arm vs base/object/obstacles)"
    assert sorted(map(repr, info["constant_pairs"])) == sorted(map(repr, constant))
    assert not set(map(repr, info["active_pairs"])) & set(map(repr, constant))
    assert len(info["active_pairs"]) + len(info["constant_pairs"]) == len(chk.pairs)
    # without fixed joints nothing is constant
    prob2 = OptProblem(tcb, n_intervals=3, duration=3.0)
    term2 = CollisionAvoidance(transport, margin=0.02, activation=1e6, object_arm="A")
    prob2.add_constraint(term2)
    prob2.set_initial(q=Q)
    info2 = prob2.term_data(prob2.terms["collision"]).info
    assert info2["constant_pairs"] == () and len(info2["active_pairs"]) == len(chk.pairs)


def _close_configuration(tcb, scene, rng, lo_d=0.005, hi_d=0.02):
    """A collision-free configuration whose closest pair is robot–obstacle, in (lo_d, hi_d) [m]."""
    chk = CollisionChecker(tcb, scene, held_object=False)
    for _ in range(20000):
        q = tcb.random_joints(rng)
        d, p = chk.min_distance(q)
        if lo_d < d < hi_d and p.kind == "robot-obstacle":
            return q, d, p, chk
    pytest.skip("no near-contact configuration found")


def test_margin_relaxed_next_to_close_boundary(tcb, transport, rng):
    q0, d0, pair, chk = _close_configuration(tcb, transport, rng)
    margin = 0.03                                    # > d0: the start is inside the margin
    q1 = q0.copy()
    i = tcb.arm("A").j_idx[-1]                      # a wrist roll: the goal keeps the start's distances
    q1[i] = np.clip(q1[i] + 0.3, tcb.lower[i], tcb.upper[i])
    assert chk.min_distance(q1)[0] > 0
    z = np.zeros(tcb.nj)
    N = 12
    prob = OptProblem(tcb, n_intervals=N, duration=12.0)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=q1, qd=z, qdd=z))
    prob.add_constraint(JointPositionLimits())
    prob.add_constraint(JointVelocityLimits())
    term = CollisionAvoidance(transport, margin=margin, held_object=False, activation=1.0, window=3)
    h = prob.add_constraint(term)
    prob.add_cost(Smoothness("jerk"))
    prob.set_initial_straight_line(q0, q1)
    data = prob.term_data(h)
    info = data.info
    assert (pair, 1) in info["relaxed"]
    # robot–box-obstacle pairs are separating planes: exact, so the bound is half coal's distance
    for (p, k), m in info["relaxed"].items():
        dp = chk.distances(q0 if k <= 3 else q1)[chk.pairs.index(p)]
        assert dp < margin and (k <= 3 or k >= N - 3)
        assert m == pytest.approx(dp / 2, abs=1e-12)
    lo, _ = term.bounds_numeric(prob.numeric_trajectory(prob._full_x0()), data)
    lo = lo.reshape(N + 1, -1)
    j = info["active_pairs"].index(pair)
    assert lo[1, j] == pytest.approx(d0 / 2) and lo[N // 2, j] == margin
    # the NLP's own rows: plane rows are bounded by m/2 (the pair's at knot 1: d0/4), smooth rows by m
    lbg = prob._built["lbg"][prob._con_slices[h.name]]
    assert np.isclose(lbg, d0 / 4, rtol=0, atol=1e-12).sum() >= 8
    assert lbg.max() == margin
    sol = prob.solve()
    assert sol.success, sol.status
    rep = verify(tcb, sol, transport, held_object=False)
    assert rep.min_clearance_m > 0.0
    # at the knots: half the boundary distance next to it, the full margin away from it
    D = np.array([chk.distances(q) for q in sol.q])[:, [chk.pairs.index(p) for p in info["active_pairs"]]]
    assert D.min() >= d0 / 2 - 1e-5
    assert D[4:N - 3].min() >= margin - 1e-5


def test_boost_between_knots(tcb, transport, rng):
    """A pair that collides between two constrained knots gets ``margin − d_min`` more margin at both;
    pairs that are not constrained there get nothing (activation is their remedy)."""
    chk = CollisionChecker(tcb, transport, held_object=False)
    for _ in range(5000):
        qa, qb = tcb.random_joints(rng), tcb.random_joints(rng)
        s = np.linspace(0, 1, 21)
        Q = qa + s[:, None] * (qb - qa)
        D = np.array([chk.distances(q) for q in Q])
        if D[[0, -1]].min() > 0.05 and D.min() < 0:
            break
    else:
        pytest.skip("no configuration pair with a collision between them")
    margin = 0.02
    prob = OptProblem(tcb, n_intervals=2, duration=2.0)
    term = CollisionAvoidance(transport, margin=margin, held_object=False, activation=1e6, window=0)
    h = prob.add_constraint(term)
    prob.set_initial(q=np.array([qa, qb, qb]))
    data = prob.term_data(h)
    t = s.copy()                                   # interval 0 = [0, 1] s, sampled 20 times
    with pytest.raises(ValueError, match="configurations of size"):
        term.with_boost(data, t, Q[:, :3], [0.0, 1.0, 2.0])
    term, n = term.with_boost(data, t, Q, [0.0, 1.0, 2.0])
    bad = [i for i, p in enumerate(chk.pairs) if D[:, i].min() < 0]
    assert n == 2 * len(bad) and len(term.margin_boost) == n
    for i in bad:
        p = chk.pairs[i]
        for k in (0, 1):
            assert term.margin_boost[(p, k)] == pytest.approx(margin - D[:, i].min())
    # the rebuilt NLP carries the larger margin on those rows
    h = prob.replace_term(h, term)
    prob.term_function(h)
    lbg = prob._built["lbg"][prob._con_slices["collision"]]
    assert lbg.max() == pytest.approx(max(margin - D[:, i].min() + margin for i in bad) / 2, rel=1e-9) or \
        lbg.max() == pytest.approx(max(margin - D[:, i].min() + margin for i in bad), rel=1e-9)
    # a pair not constrained at those knots gets no boost
    term2 = CollisionAvoidance(transport, margin=margin, held_object=False, activation=-1.0)
    prob2 = OptProblem(tcb, n_intervals=2, duration=2.0)
    h2 = prob2.add_constraint(term2)
    prob2.set_initial(q=np.array([qa, qb, qb]))
    term2b, n2 = term2.with_boost(prob2.term_data(h2), t, Q, [0.0, 1.0, 2.0])
    assert n2 == 0 and dict(term2b.margin_boost) == {}
