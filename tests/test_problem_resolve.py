"""A re-solve of an :class:`OptProblem` on the B-spline core after ``set_value`` or
``set_initial(solution=...)`` builds nothing: no kernel made or loaded, no families, no NLP
structure (counted by wrapping the builders), and its answer is checked by Pinocchio."""
from __future__ import annotations

from collections import Counter

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
    return n


def test_resolves_after_set_value_and_set_initial_build_nothing(tcb, counts):
    z = np.zeros(tcb.nj)
    q0 = np.r_[[0.3, -0.6, 0.4, -1.2, 0.2, 0.7, 0.1] * 2][:tcb.nj]
    prob = OptProblem(tcb, n_intervals=8, duration=4.0, compile_kernels=False)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(prob.qd, lower=0, upper=0, at="end")
    goal = prob.parameter(3, _hand(tcb, q0) + [0.05, 0.0, 0.05])
    ee = tcb.model.frames[tcb.arm("A").ee_frame_id].name
    prob.add_constraint(prob.frame(ee).translation - goal, lower=0, upper=0, at="end")
    prob.add_cost(Smoothness("jerk"))
    assert prob.uses_bspline()
    s1 = prob.solve()
    assert s1.success, s1.status
    assert counts["_build"] == 1 and counts["prepare"] == 1 and counts["_get"] > 0   # the counters see builds
    counts.clear()

    new = goal_value = prob._params[0].value.ravel() + np.array([0.0, 0.03, -0.02])
    prob.set_value(goal, goal_value)
    s2 = prob.solve()
    assert s2.success, s2.status
    assert np.linalg.norm(_hand(tcb, s2.q[-1]) - new) < 1e-6           # Pinocchio: the new target is reached
    assert not counts, f"a re-solve after set_value built {dict(counts)}"

    prob.set_initial(solution=s2)
    s3 = prob.solve()
    assert s3.success and s3.iterations <= 3
    np.testing.assert_allclose(s3.q, s2.q, atol=1e-6)
    # the warm-started IPOPT takes other options: its one instance is made once, then reused
    assert set(counts) <= {"__init__"} and counts["__init__"] <= 1, dict(counts)
    counts.clear()
    prob.set_initial(solution=s3)
    s4 = prob.solve()
    assert s4.success and not counts, f"a second warm re-solve built {dict(counts)}"
