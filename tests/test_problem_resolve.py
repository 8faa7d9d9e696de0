"""A re-solve of an :class:`OptProblem` on the B-spline core after ``set_value`` or
``set_initial(solution=...)`` builds nothing: no kernel made or loaded, no families, no NLP
structure, no IPOPT instance, no CasADi Function (the dense check between knots included) —
counted by wrapping the builders — and its answer is checked by Pinocchio."""
from __future__ import annotations

from collections import Counter

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from optplan.problem import OptProblem, spline_core, spline_solve
from optplan.problem import kernels as kernels_mod
from optplan.problem import nlp as nlp_mod
from optplan.problem.terms import JointBoundary, Smoothness


def _hand(robot, q):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.arm("A").ee_frame_id].translation.copy()


@pytest.fixture
def counts(monkeypatch):
    """How often each builder ran since the fixture was made (reset with ``.clear()``)."""
    n: Counter[str] = Counter()

    def wrap(owner, name, counted=None):
        orig = getattr(owner, name)

        def f(self, *a, **k):
            if counted is None or counted(self, *a, **k):
                n[name] += 1
            return orig(self, *a, **k)
        monkeypatch.setattr(owner, name, f)

    wrap(spline_core.SplineCore, "_build")                                       # an NLP structure
    wrap(spline_solve.SplineBackend, "prepare")                                  # families of the terms
    wrap(kernels_mod.KernelCache, "_get", lambda self, key, build: key not in self._fns)   # a kernel made/loaded
    wrap(nlp_mod.NlpSolver, "__init__")                                          # an IPOPT instance
    wrap(ca.Function, "__init__", lambda self, *a, **k: bool(a))                 # a Function made from expressions
    wrap(ca.Function, "map")                                                     # a mapped Function
    nlpsol = ca.nlpsol

    def counted_nlpsol(*a, **k):   # any IPOPT instance, the option checks' included
        n["nlpsol"] += 1
        return nlpsol(*a, **k)
    monkeypatch.setattr(ca, "nlpsol", counted_nlpsol)
    return n


def _reach_problem(tcb):
    """Arm A's hand to a parameter target, at rest at the end, one joint rate bounded (checked
    between knots), jerk cost: the re-solve tests' problem and its target parameter."""
    z = np.zeros(tcb.nj)
    q0 = np.r_[[0.3, -0.6, 0.4, -1.2, 0.2, 0.7, 0.1] * 2][:tcb.nj]
    prob = OptProblem(tcb, n_intervals=8, duration=4.0, compile_kernels=False)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(prob.qd, lower=0, upper=0, at="end")
    goal = prob.parameter(3, _hand(tcb, q0) + [0.05, 0.0, 0.05])
    ee = tcb.model.frames[tcb.arm("A").ee_frame_id].name
    prob.add_constraint(prob.frame(ee).translation - goal, lower=0, upper=0, at="end")
    prob.add_constraint(prob.qd[0], lower=-2.0, upper=2.0, name="slow")   # checked between knots
    prob.add_cost(Smoothness("jerk"))
    return prob, goal


def test_resolves_after_set_value_and_set_initial_build_nothing(tcb, counts):
    prob, goal = _reach_problem(tcb)
    assert prob.uses_bspline()
    s1 = prob.solve(ipopt_options={"max_iter": 200})
    assert s1.success, s1.status
    assert counts["_build"] == 1 and counts["prepare"] == 1 and counts["_get"] > 0   # the counters see builds
    assert counts["__init__"] >= 1 and counts["nlpsol"] >= 1                        # ... and instances
    counts.clear()

    new = goal_value = prob._params[0].value.ravel() + np.array([0.0, 0.03, -0.02])
    prob.set_value(goal, goal_value)
    s2 = prob.solve(ipopt_options={"max_iter": 200})
    assert s2.success, s2.status
    assert np.linalg.norm(_hand(tcb, s2.q[-1]) - new) < 1e-6           # Pinocchio: the new target is reached
    assert not counts, f"a re-solve after set_value built {dict(counts)}"

    prob.set_initial(solution=s2)
    s3 = prob.solve(ipopt_options={"max_iter": 200})
    assert s3.success and s3.iterations <= 3
    np.testing.assert_allclose(s3.q, s2.q, atol=1e-6)
    # the warm-started IPOPT takes other options: its instance was made with the first build
    assert not counts, f"the first warm re-solve built {dict(counts)}"
    prob.set_initial(solution=s3)
    s4 = prob.solve(ipopt_options={"max_iter": 200})
    assert s4.success and not counts, f"a second warm re-solve built {dict(counts)}"
    # the benchmark's order: a parameter changed after warm re-solves (the cold instance again),
    # then moved back (a value seen before)
    for value in (goal_value + np.array([0.0, 0.01, 0.0]), goal_value):
        prob.set_value(goal, value)
        s5 = prob.solve(ipopt_options={"max_iter": 200})
        assert s5.success and np.linalg.norm(_hand(tcb, s5.q[-1]) - value) < 1e-6, s5.status
        assert not counts, f"a re-solve after set_value that followed warm re-solves built {dict(counts)}"
    # the dense check ran on every re-solve, with the expression's function of the first solve
    assert np.abs(s4.sample(np.linspace(0.0, 4.0, 81), "slow")).max() <= 2.0 + 1e-6


def test_resolves_leave_no_reference_cycles(tcb):
    """Re-solves after ``set_value`` and ``set_initial(solution=...)`` free what they make by
    reference counting: no reference cycle, so no garbage collection of theirs lands on a later
    re-solve (a collection of the benchmark's own garbage cost the tenth re-solve after
    ``set_value`` 2-5 ms)."""
    import gc

    prob, goal = _reach_problem(tcb)
    sol = prob.solve()
    prob.set_initial(solution=sol)
    assert sol.success and prob.solve().success          # both IPOPT instances used once
    value = prob._params[0].value.ravel().copy()
    flags = gc.get_debug()
    gc.collect()
    gc.set_debug(gc.DEBUG_SAVEALL)      # what a collection finds is kept in gc.garbage
    try:
        for i in range(3):
            prob.set_value(goal, value + [0.0, 0.01 * (i % 2), 0.0])
            s = prob.solve()
            prob.set_initial(solution=s)
            assert s.success and prob.solve().success
        gc.collect()
        cyclic = [type(o).__name__ for o in gc.garbage]
    finally:
        gc.set_debug(flags)
        gc.garbage.clear()
    assert not cyclic, f"re-solves left {len(cyclic)} objects in reference cycles: {sorted(set(cyclic))}"


def test_a_problem_solved_once_makes_one_ipopt_instance(tcb, counts):
    """``prepare_warm_start = False`` (the pipeline's segments): the first build makes only the
    instance it solves with; the warm-started one waits for a warm re-solve."""
    z = np.zeros(tcb.nj)
    q0 = np.r_[[0.3, -0.6, 0.4, -1.2, 0.2, 0.7, 0.1] * 2][:tcb.nj]
    prob = OptProblem(tcb, n_intervals=6, duration=3.0, compile_kernels=False)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=q0 + 0.2, qd=z, qdd=z))
    prob.add_cost(Smoothness("jerk"))
    prob.prepare_warm_start = False
    s1 = prob.solve()
    assert s1.success and counts["nlpsol"] == 1, dict(counts)
    counts.clear()
    prob.set_initial(solution=s1)
    assert prob.solve().success and counts["nlpsol"] == 1, dict(counts)


def test_terms_say_whether_they_read_the_base_attitude(tcb):
    from optplan import RobotModel
    from optplan.problem.terms import JointPositionLimits

    ff = RobotModel.from_name("eba_ffsr")
    prob = OptProblem(ff, n_intervals=4, duration=2.0)
    joint = prob.add_constraint(prob.qd[7:], lower=0, upper=0)
    hand = prob.add_constraint(prob.frame("a_ee").translation, lower=-5, upper=5)
    com = prob.add_constraint(prob.com, lower=-5, upper=5)
    assert not joint.term.reads_base_attitude(ff)
    assert hand.term.reads_base_attitude(ff) and com.term.reads_base_attitude(ff)
    assert not JointPositionLimits().reads_base_attitude(ff)
    fixed = OptProblem(tcb, n_intervals=4, duration=2.0)
    ee = tcb.model.frames[tcb.arm("A").ee_frame_id].name
    assert not fixed.add_constraint(fixed.frame(ee).translation, lower=-5, upper=5).term.reads_base_attitude(tcb)


def test_floating_resolves_make_no_data_twins_or_matrices(counts, monkeypatch):
    """The free-floating reach (a frame target as a parameter, arm B still, the base attitude
    restored): its re-solves build nothing (the counters above) and the numbers of the solve path
    are made once too — no Pinocchio ``Data``, no B-spline knot matrices, no term twin for the
    dense check (made and validated with the first solve), no CasADi matrix from an array of a
    sampled trajectory or a solution (the numbers go through function buffers). Its answers are
    checked by Pinocchio."""
    from optplan import RobotModel
    from optplan.problem import bspline
    from optplan.problem.frame_terms import BaseAttitude
    from optplan.problem.terms import Term

    ff = RobotModel.from_name("eba_ffsr")
    q0 = np.r_[[0.3, -0.6, 0.4, -1.2, 0.2, 0.7, 0.1] * 2]
    data = ff.model.createData()   # the test's own, made before the counters

    def wrap(owner, name, key, counted=None):
        orig = getattr(owner, name)

        def f(*a, **k):
            if counted is None or counted(*a, **k):
                counts[key] += 1
            return orig(*a, **k)
        monkeypatch.setattr(owner, name, f)

    wrap(pin.Model, "createData", "pinocchio Data")
    wrap(bspline, "knot_matrices", "knot matrices")
    wrap(Term, "__post_init__", "term made")
    wrap(ca.DM, "__init__", "DM of > 64 numbers",
         lambda self, *a: any(isinstance(v, (np.ndarray, list)) and np.size(v) > 64 for v in a))

    def hand(sol, k):
        pin.framesForwardKinematics(ff.model, data, np.r_[sol.base_position[k], sol.base_quat[k], sol.q[k]])
        return data.oMf[ff.model.getFrameId("a_ee")].translation.copy()

    prob = OptProblem(ff, n_intervals=20, duration=20.0, compile_kernels=False)
    prob.add_constraint(prob.q, lower=q0, upper=q0, at="start")
    prob.add_constraint(prob.qd, lower=0, upper=0, at=[0, 20])
    prob.add_constraint(prob.qdd, lower=0, upper=0, at=[0, 20])
    still = prob.add_constraint(prob.qd[7:], lower=0, upper=0)        # checked between knots
    pin.framesForwardKinematics(ff.model, data, ff.configuration(q0))
    target = data.oMf[ff.model.getFrameId("a_ee")].translation + 0.3 * np.array([0.6, 0.0, 0.8])
    goal = prob.parameter(3, target)
    prob.add_constraint(prob.frame("a_ee").translation - goal, lower=0, upper=0, at="end")
    prob.add_constraint(BaseAttitude(at="end"))
    prob.add_cost(Smoothness("jerk"))
    s1 = prob.solve()
    assert s1.success, s1.status
    assert counts["pinocchio Data"] > 0 and counts["term made"] > 0 and counts["_build"] == 1   # the counters see
    counts.clear()

    prob.set_value(goal, target + np.array([0.0, 0.02, 0.0]))
    s2 = prob.solve()
    assert s2.success, s2.status
    assert np.linalg.norm(hand(s2, -1) - (target + [0.0, 0.02, 0.0])) < 1e-5     # Pinocchio: the new target
    prob.set_initial(solution=s2)
    s3 = prob.solve()
    assert s3.success and s3.iterations <= 5
    assert not counts, f"re-solves of the floating reach made {dict(counts)}"
    # the dense check still ran, on the first solve's twin: arm B is still between the knots
    t = np.linspace(0.0, 20.0, 161)
    assert np.abs(s3.sample(t)["qd"][:, 7:]).max() <= 1e-6
    assert np.abs(s3.sample(t, still)).max() <= 1e-6


def test_the_dense_checks_twin_is_kept_per_term_and_made_again_after_a_change(tcb):
    """The dense check's twin of a term (``Term.sampled``) is made once per term — and again when a
    field of the term is set in place; a term that is its own twin is not kept alive by it."""
    import gc
    import weakref

    from optplan.problem import ClosedChain
    from optplan.problem.guarantees import _sampled
    from optplan.problem.terms import JointBoundary

    cc = ClosedChain("A", "B", relative=pin.SE3(np.eye(3), np.array([0.0, 0.4, 0.0])), interior=1, skip_pinned=True)
    twin = _sampled(cc)
    assert twin.interior == 0 and not twin.skip_pinned and _sampled(cc) is twin
    with pytest.warns(DeprecationWarning):
        cc.relative = pin.SE3(np.eye(3), np.array([0.0, 0.5, 0.0]))
    again = _sampled(cc)
    assert again is not twin and np.allclose(again.relative.translation, [0.0, 0.5, 0.0])
    assert _sampled(JointBoundary("start", q=np.zeros(3))) is None   # tied to given knots
    prob = OptProblem(tcb, n_intervals=4, duration=2.0)
    own = prob.add_constraint(prob.qd[0], lower=-1.0, upper=1.0).term   # along the whole trajectory: its own twin
    assert _sampled(own) is own and _sampled(own) is own
    refs = [weakref.ref(cc), weakref.ref(own)]
    del cc, twin, again, own, prob
    gc.collect()
    assert all(r() is None for r in refs), "the kept twins hold their terms alive"


def test_a_closed_chain_resolve_makes_no_pinocchio_data_or_twin(tcb, counts, monkeypatch):
    """The dense check of a closed chain (Pinocchio placements of both hands at every sample)
    works in the robot's own ``Data`` and the term's kept twin: a re-solve makes neither; the
    check still ran (the chain holds between the knots, by Pinocchio)."""
    from optplan.problem import ClosedChain
    from optplan.problem.terms import Term

    z = np.zeros(tcb.nj)
    q0 = np.r_[[0.3, -0.6, 0.4, -1.2, 0.2, 0.7, 0.1] * 2][:tcb.nj]
    prob = OptProblem(tcb, n_intervals=6, duration=3.0, compile_kernels=False)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(prob.qd[0], lower=0.05, upper=0.2, at=3)        # the arms move
    cc = prob.add_constraint(ClosedChain.from_configuration(tcb, tcb.configuration(q0)))
    prob.add_cost(Smoothness("jerk"))
    s1 = prob.solve()
    assert s1.success, s1.status
    for owner, name, key in ((pin.Model, "createData", "pinocchio Data"), (Term, "__post_init__", "term made")):
        orig = getattr(owner, name)

        def f(*a, _orig=orig, _key=key, **k):
            counts[_key] += 1
            return _orig(*a, **k)
        monkeypatch.setattr(owner, name, f)
    counts.clear()
    prob.set_initial(solution=s1)
    s2 = prob.solve()
    assert s2.success and not counts, f"a closed-chain re-solve made {dict(counts)}"
    assert np.abs(s2.sample(np.linspace(0.0, 3.0, 121), cc)[:, :6]).max() < 1e-3   # the chain between the knots
    assert np.ptp(s2.q[:, 0]) > 0.01
