"""The dense check between knots on the B-spline core keeps its last few results per problem and
returns one only for inputs equal bit for bit (the solution, the parameters' values, the terms
and their fields, the options): what a re-solve recomputes is counted here, not timed, and
every kept answer is compared with the check computed again without the kept results."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from optplan.problem import OptProblem, guarantees
from optplan.problem.guarantees import GuaranteeOptions, check_between_knots
from optplan.problem.terms import JointBoundary, Smoothness


def _problem(tcb):
    """Arm A's hand to a parameter target, joint 0's rate bounded (checked between knots)."""
    import pinocchio as pin

    z = np.zeros(tcb.nj)
    q0 = np.r_[[0.3, -0.6, 0.4, -1.2, 0.2, 0.7, 0.1] * 2][:tcb.nj]
    data = tcb.model.createData()
    pin.framesForwardKinematics(tcb.model, data, tcb.configuration(q0))
    hand = data.oMf[tcb.arm("A").ee_frame_id].translation.copy()
    # 7 intervals: not the structure of another test file's problem (its first build is counted there)
    prob = OptProblem(tcb, n_intervals=7, duration=4.0, compile_kernels=False)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(prob.qd, lower=0, upper=0, at="end")
    goal = prob.parameter(3, hand + [0.05, 0.0, 0.05])
    ee = tcb.model.frames[tcb.arm("A").ee_frame_id].name
    prob.add_constraint(prob.frame(ee).translation - goal, lower=0, upper=0, at="end")
    slow = prob.add_constraint(prob.qd[0], lower=-2.0, upper=2.0, name="slow")
    prob.add_cost(Smoothness("jerk"))
    return prob, goal, slow


def _fresh(prob, sol, options=None):
    """The check computed, the kept results left alone."""
    kept = guarantees._CHECKS_KEPT
    guarantees._CHECKS_KEPT = 0
    try:
        return check_between_knots(prob, sol, options)
    finally:
        guarantees._CHECKS_KEPT = kept


def _count(fn):
    before = dict(guarantees.COUNTS)
    out = fn()
    return out, {k: guarantees.COUNTS[k] - before[k] for k in before}


def test_a_resolve_that_reproduces_a_solution_reuses_its_check(tcb):
    prob, goal, _ = _problem(tcb)
    s1, n = _count(prob.solve)
    assert s1.success and n == {"computed": 1, "reused": 0}, n
    # a warm start from the solution: IPOPT's answer, bit for bit, is checked once per answer
    answers = []
    for _ in range(3):
        prob.set_initial(solution=s1)
        s, n = _count(prob.solve)
        assert s.success and n["computed"] + n["reused"] == 1, n
        answers.append((s.x.tobytes(), n["reused"]))
    for i, (x, reused) in enumerate(answers):
        seen = x == s1.x.tobytes() or any(x == a for a, _ in answers[:i])
        assert reused == int(seen), (i, reused, seen)
    assert answers[2][1] == 1      # the same warm start twice: the same answer
    # a new parameter value: checked; its check is kept, equal to one computed again
    value = prob._params[0].value.ravel().copy()
    prob.set_value(goal, value + [0.0, 0.01, 0.0])
    s2, n = _count(prob.solve)
    assert s2.success and n == {"computed": 1, "reused": 0}, n
    kept, n = _count(lambda: check_between_knots(prob, s2))
    assert n == {"computed": 0, "reused": 1} and kept == _fresh(prob, s2) == []


def test_any_changed_input_is_checked_again(tcb):
    prob, goal, slow = _problem(tcb)
    sol = prob.solve()
    assert sol.success
    assert _count(lambda: check_between_knots(prob, sol))[1] == {"computed": 0, "reused": 1}
    # other options
    o = GuaranteeOptions(density=12)
    assert _count(lambda: check_between_knots(prob, sol, o))[1] == {"computed": 1, "reused": 0}
    # another parameter value, the same solution (an expression reads the parameter's value)
    value = prob._params[0].value.ravel().copy()
    prob.set_value(goal, value + [0.0, 0.0, 1e-12])
    assert _count(lambda: check_between_knots(prob, sol))[1] == {"computed": 1, "reused": 0}
    prob.set_value(goal, value)
    assert _count(lambda: check_between_knots(prob, sol))[1] == {"computed": 0, "reused": 1}
    # a trajectory moved by one ulp at one knot
    q = sol.q.copy()
    q[4, 0] = np.nextafter(q[4, 0], np.inf)
    moved = dataclasses.replace(sol, q=q)
    assert _count(lambda: check_between_knots(prob, moved))[1] == {"computed": 1, "reused": 0}
    # a field of a checked term set in place: the kept (empty) answer is not returned
    peak = float(np.abs(sol.sample(np.linspace(0.0, 4.0, 161))["qd"][:, 0]).max())
    assert peak > 0.003     # a violation of 0.8 × peak is past the tolerance (1e-3)
    with pytest.warns(DeprecationWarning):
        slow.term.upper = 0.2 * peak
    got, n = _count(lambda: check_between_knots(prob, sol))
    assert n == {"computed": 1, "reused": 0}
    assert got and got == _fresh(prob, sol) and {v.term for v in got} == {"slow"}
    again, n = _count(lambda: check_between_knots(prob, sol))
    assert n == {"computed": 0, "reused": 1} and again == got and again is not got


def test_kept_checks_keep_no_problem_alive(tcb):
    import gc
    import weakref

    prob, _, _ = _problem(tcb)
    assert prob.solve().success
    assert prob in guarantees._CHECKS
    ref = weakref.ref(prob)
    del prob
    gc.collect()
    assert ref() is None


def test_an_array_bound_changed_in_place_is_checked_again(tcb):
    """A term's array field changed in place (the same object): its numbers are in the inputs."""
    prob, _, _ = _problem(tcb)
    both = prob.add_constraint(prob.qd[:2], lower=np.array([-2.0, -2.0]), upper=np.array([2.0, 2.0]), name="both")
    sol = prob.solve()
    assert sol.success and isinstance(both.term.upper, np.ndarray)
    assert _count(lambda: check_between_knots(prob, sol))[1] == {"computed": 0, "reused": 1}
    peak = float(np.abs(sol.sample(np.linspace(0.0, 4.0, 161))["qd"][:, 0]).max())
    assert peak > 0.003
    both.term.upper[0] = 0.2 * peak            # the same array object, another number
    got, n = _count(lambda: check_between_knots(prob, sol))
    assert n == {"computed": 1, "reused": 0}   # not the kept answer: whatever the term reads now
    assert got == _fresh(prob, sol)
