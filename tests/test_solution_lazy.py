"""A re-solve on the B-spline core computes only what it returns: the solution's ``terms`` are
evaluated when first read (once), equal to their evaluation through the term handles and to
the objective; the constraint rows go through a kept function buffer with the same numbers as
CasADi's ordinary call; counted by ``spline_solve.COUNTS``. Untimed."""
from __future__ import annotations

import pickle

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from optplan.problem import OptProblem, spline_solve
from optplan.problem.solution import LazyTerms
from optplan.problem.terms import JointBoundary, Smoothness


@pytest.fixture(autouse=True, scope="module")
def _forget_kernels():
    """After these tests the process forgets the kernels they made (the disk cache stays): a
    later test that counts the kernels a first build makes sees its own."""
    yield
    from optplan.bench.modelling import _forget_memory

    _forget_memory()


def _hand(robot, q):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.arm("A").ee_frame_id].translation.copy()


def _problem(tcb):
    """Arm A's hand to a parameter target, at rest at the end, one joint rate bounded, a jerk
    and a weighted joint-rate cost (two cost terms)."""
    z = np.zeros(tcb.nj)
    q0 = np.r_[[0.3, -0.6, 0.4, -1.2, 0.2, 0.7, 0.1] * 2][:tcb.nj]
    prob = OptProblem(tcb, n_intervals=8, duration=4.0, compile_kernels=False)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(prob.qd, lower=0, upper=0, at="end")
    goal = prob.parameter(3, _hand(tcb, q0) + [0.05, 0.0, 0.05])
    ee = tcb.model.frames[tcb.arm("A").ee_frame_id].name
    prob.add_constraint(prob.frame(ee).translation - goal, lower=0, upper=0, at="end", name="reach")
    prob.add_constraint(prob.qd[0], lower=-2.0, upper=2.0, name="slow")
    prob.add_cost(Smoothness("jerk"), name="jerk")
    prob.add_cost(ca.sumsqr(prob.qd), weight=0.01, name="rates")
    return prob, goal


def test_terms_lazy_once_and_equal_to_the_handles(tcb):
    prob, goal = _problem(tcb)
    s1 = prob.solve(ipopt_options={"max_iter": 200})
    assert s1.success, s1.status
    c = dict(spline_solve.COUNTS)
    # re-solves after set_value and set_initial(solution=...): no build, no solver, no terms
    prob.set_value(goal, np.asarray(prob._params[0].value).ravel() + [0.0, 0.02, -0.01])
    s2 = prob.solve(ipopt_options={"max_iter": 200})
    prob.set_initial(solution=s2)
    s3 = prob.solve(ipopt_options={"max_iter": 200})
    assert s2.success and s3.success
    d = {k: spline_solve.COUNTS[k] - c[k] for k in c}
    assert d["prepared"] == 0 and d["solvers_created"] == 0
    assert d["solutions"] == 2 and d["terms_computed"] == 0
    assert isinstance(s2.terms, LazyTerms) and not s2.terms.computed and not s3.terms.computed
    # read: computed once, for this solution alone
    t2 = dict(s2.terms)
    assert s2.terms.computed and not s3.terms.computed
    assert {"jerk", "rates", "reach", "slow", "dynamics"} <= set(t2)
    _ = s2.terms["jerk"], list(s2.terms), len(s2.terms)
    assert spline_solve.COUNTS["terms_computed"] - c["terms_computed"] == 1
    # equal to the values through the handles (the evaluator: its own kernel calls), and the cost
    # terms add up to the objective
    for name in ("jerk", "rates"):
        assert t2[name] == pytest.approx(float(s2.value(prob.terms[name])), rel=1e-12, abs=1e-15)
    assert t2["jerk"] + t2["rates"] == pytest.approx(s2.cost, rel=1e-9)
    for name in ("reach", "slow"):
        assert t2[name] == pytest.approx(float(np.max(s2.violation(prob.terms[name]), initial=0.0)), abs=1e-12)
    # the terms of s2 were taken at its solve: a later solve does not change them
    t3 = dict(s3.terms)
    assert dict(s2.terms) == t2 and set(t3) == set(t2)
    # read-only, compares and pickles as the plain values
    with pytest.raises(TypeError):
        s2.terms["jerk"] = 0.0   # type: ignore[index]
    assert s2.terms == t2 and pickle.loads(pickle.dumps(s2.terms)) == t2
    back = pickle.loads(pickle.dumps(s2))
    assert dict(back.terms) == t2


def test_constraint_rows_through_the_kept_buffer_equal_casadi(tcb):
    prob, goal = _problem(tcb)
    s1 = prob.solve(ipopt_options={"max_iter": 200})
    be = prob._spline
    kept = be._gbuf
    assert kept is not None   # the buffer is kept with the backend and used again
    prob.set_value(goal, np.asarray(prob._params[0].value).ravel() + [0.0, 0.0, 0.01])
    s2 = prob.solve(ipopt_options={"max_iter": 200})
    assert be._gbuf is kept
    for s in (s1, s2):
        gfun = kept[0]
        p = s.evaluator.p
        ref = np.asarray(gfun(s.x, p), float).ravel()      # CasADi's ordinary call
        assert np.array_equal(be._g_at(gfun, np.asarray(s.x), p), ref)
        lbg, ubg = s.evaluator.st["lbg"], s.evaluator.st["ubg"]
        viol = max(float(np.max(np.maximum(np.maximum(lbg - ref, ref - ubg), 0.0))), 0.0)
        assert s.max_constraint_violation >= viol   # max(rows, variable bounds)
        assert s.terms["dynamics"] <= viol
