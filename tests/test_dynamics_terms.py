"""Torque terms of OptProblem (optplan.problem.dynamics_terms): rows and cost against their
Pinocchio twins, the effort limits, and a solve where a torque limit is active and holds between
knots (checked densely with ``pinocchio.rnea``, independently of the problem's own check)."""
from __future__ import annotations

import copy

import numpy as np
import pinocchio as pin
import pytest

from optplan.errors import ConfigurationError
from optplan.model.robot import RobotModel
from optplan.problem import JointBoundary, OptProblem, Smoothness
from optplan.problem.dynamics_terms import JointTorqueLimits, TorqueCost, effort_limits, joint_torques_numeric
from optplan.problem.guarantees import GuaranteeOptions, check_between_knots


def _random_problem(robot, rng, N=16, **kw):
    prob = OptProblem(robot, n_intervals=N, duration=2.0)
    h = prob.add_constraint(JointTorqueLimits(limit=1e4, **kw))
    c = prob.add_cost(TorqueCost(weights=rng.uniform(0.5, 2.0, robot.nj)))
    q = np.array([robot.random_joints(rng) for _ in range(4)]) * 0.5
    prob.set_initial(q=q)
    return prob, h, c


@pytest.mark.parametrize("name", ["tcbirrt_dual_arm", "eba_ffsr"])
def test_torque_rows_and_cost_match_pinocchio(name, rng):
    robot = RobotModel.from_name(name)
    prob, h, c = _random_problem(robot, rng)
    x0 = prob.initial_guess
    traj = prob.numeric_trajectory(x0)
    rows = np.array(prob.term_function(h)(x0)).ravel()
    ref = h.term.numeric(traj)
    assert np.abs(rows - ref).max() <= 1e-9 * max(1.0, np.abs(ref).max())
    cost = float(prob.term_function(c)(x0))
    ref_c = c.term.cost_numeric(traj)
    assert cost == pytest.approx(ref_c, rel=1e-9)
    # Simpson's rule vs a dense trapezoid of the exact trajectory (independent quadrature)
    t = np.linspace(0.0, 2.0, 4001)
    qs = _sample(traj, t)
    w = np.asarray(c.term.weights, float)
    f = np.array([w @ joint_torques_numeric(robot, *x) ** 2 for x in zip(*qs)])
    assert cost == pytest.approx(np.trapezoid(f, t), rel=2e-3)


def _sample(traj, t):
    h = traj.h
    k = np.clip((t / h).astype(int), 0, traj.N - 1)
    tau = (t - k * h)[:, None]
    q0, v0, a0, j0 = traj.q[k], traj.qd[k], traj.qdd[k], traj.jerk[k]
    return (q0 + tau * v0 + tau**2 / 2 * a0 + tau**3 / 6 * j0, v0 + tau * a0 + tau**2 / 2 * j0, a0 + tau * j0)


def test_interior_points_add_rows(rng):
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    prob, h, _ = _random_problem(robot, rng, interior=2)
    d = prob.term_data(h)
    assert d.points[:4] == (0, (0, 1 / 3), (0, 2 / 3), 1) and d.n_rows == (16 + 16 * 2 + 1) * robot.nj
    x0 = prob.initial_guess
    traj = prob.numeric_trajectory(x0)
    rows = np.array(prob.term_function(h)(x0)).ravel().reshape(-1, robot.nj)
    q, v, a = (x[0] for x in _sample(traj, np.array([traj.h / 3])))
    np.testing.assert_allclose(rows[1], joint_torques_numeric(robot, q, v, a), rtol=1e-9, atol=1e-9)


def test_effort_limits_and_errors():
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    np.testing.assert_array_equal(effort_limits(robot), robot.model.effortLimit)
    lim = effort_limits(robot, {robot.joint_names[2]: 7.0})
    assert lim[2] == 7.0 and lim[0] == robot.model.effortLimit[0]
    with pytest.raises(ConfigurationError, match="unknown joint 'nope'"):
        effort_limits(robot, {"nope": 1.0})
    with pytest.raises(ConfigurationError, match="expected values > 0"):
        JointTorqueLimits(limit=[-1.0] * 14)
    with pytest.raises(ConfigurationError, match="limit\\['a'\\]"):
        JointTorqueLimits(limit={"a": float("nan")})
    bare = copy.copy(robot)
    bare.model = robot.model.copy()
    bare.model.effortLimit[3] = 0.0                     # a URDF without <limit effort>
    with pytest.raises(ConfigurationError, match=f"no effort limit for joints \\['{robot.joint_names[3]}'\\]"):
        JointTorqueLimits().limits(bare)
    assert JointTorqueLimits(limit={robot.joint_names[3]: 5.0}).limits(bare)[1][3] == 5.0
    with pytest.raises(ConfigurationError, match="weights"):
        TorqueCost(weights=-1.0)
    ff = RobotModel.from_name("eba_ffsr")               # the base's 6 rows are not joints
    assert effort_limits(ff).shape == (ff.nj,)


# --------------------------------------------------------------------------- an active limit
LIMIT_J1 = 2800.0   # [N·m] below the 3351 N·m the unconstrained move needs on joint a_joint2


def _move(robot):
    q0 = robot.neutral()
    q1 = q0.copy()
    q1[1] += 0.8
    q1[3] += 0.6
    z = np.zeros(robot.nj)
    prob = OptProblem(robot, n_intervals=12, duration=1.0)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=q1, qd=z, qdd=z))
    prob.add_cost(Smoothness("jerk"))
    lim = np.full(robot.nj, 1e5)
    lim[1] = LIMIT_J1
    h = prob.add_constraint(JointTorqueLimits(limit=lim))
    prob.set_initial_straight_line(q0, q1)
    return prob, h


def _dense_torque(robot, sol, per_interval=20):
    t = np.linspace(0.0, sol.duration, per_interval * (len(sol.t) - 1) + 1)
    s = sol.sample(t)
    m, d = robot.model, robot.model.createData()
    return np.array([pin.rnea(m, d, q, v, a) for q, v, a in zip(s["q"], s["qd"], s["qdd"])])


def test_active_torque_limit_holds_between_knots():
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    o = GuaranteeOptions()
    allowed = LIMIT_J1 + o.tol + o.rel_tol * LIMIT_J1
    # on the knots alone the limit holds at the knots and is exceeded between them
    prob, h = _move(robot)
    knots = prob.solve_knots()
    assert knots.success
    assert np.abs(_dense_torque(robot, knots)[:, 1]).max() > allowed
    viol = check_between_knots(prob, knots)
    assert viol and viol[0].term == h.name and viol[0].component == robot.joint_names[1]
    # solve(): refined until the limit holds densely; the limit is active with a non-zero dual
    prob, h = _move(robot)
    sol = prob.solve()
    assert sol.success, (sol.status, sol.between_knots[:2])
    tau_k = sol.value(h)[:, 1]
    assert np.abs(tau_k).max() == pytest.approx(LIMIT_J1, abs=1e-3)           # active at knots
    dual = sol.dual(h)[:, 1]
    assert np.abs(dual).max() > 1e-2 and np.all(dual[tau_k > LIMIT_J1 - 1e-3] <= 0)   # an upper bound: ≤ 0
    assert np.abs(dual[np.abs(tau_k) < LIMIT_J1 - 1.0]).max() < 1e-6                   # inactive rows: 0
    dense = _dense_torque(robot, sol)                                          # 20× the knots
    assert np.abs(dense[:, 1]).max() <= allowed
    assert prob.N > 12 and sol.attempts[-1].label == "refine"


# --------------------------------------------------------------------------- torques as expressions
def test_tau_expression_matches_pinocchio_and_limits_it_on_the_kernel_core():
    """``prob.tau`` is a one-line expression on the B-spline core: its values at the knots are
    Pinocchio's ``rnea`` of the sampled solution, and a bound on it holds densely after ``solve``."""
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    q0 = robot.neutral()
    q1 = q0.copy()
    q1[1] += 0.8
    q1[3] += 0.6
    z = np.zeros(robot.nj)
    prob = OptProblem(robot, n_intervals=12, duration=1.0)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=q1, qd=z, qdd=z))
    prob.add_cost(Smoothness("jerk"))
    h = prob.add_constraint(prob.tau[1], lower=-LIMIT_J1, upper=LIMIT_J1, name="tau_j2")
    prob.set_initial_straight_line(q0, q1)
    assert prob._mode() == "bspline"
    sol = prob.solve()
    assert sol.success, (sol.status, sol.between_knots[:2])
    tk = np.asarray(sol.value(h)).ravel()
    ref = _dense_torque(robot, sol, per_interval=1)[:, 1]
    np.testing.assert_allclose(tk, ref, rtol=1e-7, atol=1e-6)                 # the expression = Pinocchio
    assert np.abs(tk).max() == pytest.approx(LIMIT_J1, abs=1.0)                # active
    o = GuaranteeOptions()
    assert np.abs(_dense_torque(robot, sol)[:, 1]).max() <= LIMIT_J1 + o.tol + o.rel_tol * LIMIT_J1
    w = prob.base_wrench                                                          # fixed base: 6 rows per point
    assert w.shape == (6, 1)
