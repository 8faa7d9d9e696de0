"""What ``success`` guarantees between knots (optplan.problem.guarantees).

Independent references: ``optplan.verification.verify`` (coal at 10× the knot density, written
apart from the dense check) and exact coal distances; the knot-only solve (``solve_knots`` or
``guarantees=False``) as the case that the dense check must catch.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from optplan.collision.checker import CollisionChecker
from optplan.errors import OptionError
from optplan.model.robot import RobotModel
from optplan.problem import CollisionAvoidance, IpoptStatus, JointBoundary, OptProblem, Smoothness
from optplan.problem.guarantees import GuaranteeOptions, check_between_knots
from optplan.scene import Obstacle, Scene
from optplan.verification import verify


# --------------------------------------------------------------------------- the UR5 case
def _ur5(tmp_path_factory) -> RobotModel:
    """UR5 of example-robot-data, each collision mesh replaced by its bounding box (the NLP's
    collision rows model boxes and capsules, not meshes)."""
    from optplan.model._robot_data import example_robot_data_dir
    from optplan.model.mesh_boxes import collision_meshes_as_boxes

    share = example_robot_data_dir()
    urdf = None if share is None else share / "robots/ur_description/urdf/ur5_robot.urdf"
    if urdf is None or not urdf.exists():
        pytest.skip("example-robot-data is not installed (extra 'robots')")
    return RobotModel.from_urdf(collision_meshes_as_boxes(urdf, package_dirs=[share]), arms={"A": "tool0"},
                                name="ur5")


Q0 = np.array([-1.2, -1.2, 1.5, -1.9, -1.57, 0.0])
Q1 = np.array([1.2, -1.2, 1.5, -1.9, -1.57, 0.0])
MARGIN = 0.02


@pytest.fixture(scope="module")
def ur5_case(tmp_path_factory):
    r = _ur5(tmp_path_factory)
    d = r.model.createData()
    pin.framesForwardKinematics(r.model, d, (Q0 + Q1) / 2)
    pm = d.oMf[r.frame_id("tool0")].translation
    c = np.r_[pm[:2] + 0.09 * pm[:2] / np.linalg.norm(pm[:2]), pm[2]]   # a box just outside the tool's arc
    scene = Scene("ur5_box", None, (Obstacle("box", "box", pin.SE3(np.eye(3), c), size=(0.1, 0.1, 0.3)),))
    return r, scene


def _ur5_problem(r, scene, N=10):
    z = np.zeros(6)
    prob = OptProblem(r, n_intervals=N, duration=3.0)
    prob.add_constraint(JointBoundary("start", q=Q0, qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=Q1, qd=z, qdd=z))
    prob.add_cost(Smoothness("jerk"))
    h = prob.add_constraint(CollisionAvoidance(scene, margin=MARGIN, self_collision=False))
    prob.set_initial_straight_line(Q0, Q1)
    return prob, h


def test_ur5_margin_missed_between_knots_is_caught(ur5_case):
    """The knot-only solve holds the margin at the knots and cuts it between them (the case a user
    reported as success); the dense check names the pair, the time and the amount."""
    r, scene = ur5_case
    prob, h = _ur5_problem(r, scene)
    sol = prob.solve_knots()
    assert sol.success
    assert sol.violation(h).max() < 1e-6                       # every knot row holds
    rep = verify(r, sol, scene)
    assert rep.min_clearance_m < MARGIN - 0.005                # 10× denser: the margin is missed
    viol = check_between_knots(prob, sol)
    assert viol and viol[0].term == h.name and "box" in viol[0].component
    assert viol[0].amount == pytest.approx(MARGIN - rep.min_clearance_m, abs=1e-6)
    assert 0 < viol[0].t < 3.0 and 0 <= viol[0].interval < 10
    assert "at t=" in str(viol[0])


def test_ur5_solve_refines_until_the_margin_holds(ur5_case):
    r, scene = ur5_case
    prob, h = _ur5_problem(r, scene)
    sol = prob.solve()
    o = GuaranteeOptions()
    assert sol.success, (sol.status, sol.between_knots[:3])
    assert [a.label for a in sol.attempts][0] == "" and len(sol.attempts) > 1   # it had to re-solve
    rep = verify(r, sol, scene)
    assert rep.min_clearance_m >= MARGIN - (o.tol + o.rel_tol * MARGIN)
    assert sol.between_knots == () and check_between_knots(prob, sol) == []
    assert sol.violation(h).shape[0] > 0                       # the user's handle still evaluates


def test_violation_is_a_status_when_refinement_is_off(ur5_case):
    r, scene = ur5_case
    prob, h = _ur5_problem(r, scene)
    sol = prob.solve(guarantees=GuaranteeOptions(collision_retries=0, refinements=0))
    assert not sol.success and sol.status is IpoptStatus.VIOLATED_BETWEEN_KNOTS
    assert not sol.status.succeeded
    assert sol.between_knots and sol.between_knots[0].term == h.name
    assert prob.N == 10


def test_guarantee_options_refuse_bad_values():
    for kw in ({"density": 5}, {"tol": -1.0}, {"growth": 1}, {"refinements": 1.5}):
        with pytest.raises(OptionError, match=next(iter(kw))):
            GuaranteeOptions(**kw)
    with pytest.raises(OptionError, match="guarantees"):
        GuaranteeOptions.coerce("yes")


# --------------------------------------------------------------------------- property
@pytest.fixture(scope="module")
def tcb_arm():
    return RobotModel.from_name("tcbirrt_dual_arm")


@settings(max_examples=5, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(offset=st.floats(0.0, 0.12), side=st.floats(0.0, 2 * np.pi), size=st.floats(0.04, 0.12),
       margin=st.floats(0.005, 0.04), frac=st.floats(0.3, 0.7))
def test_success_implies_no_dense_violation(tcb_arm, offset, side, size, margin, frac):
    """Random box obstacles near a straight joint-space move of one arm, random margins: whenever
    ``solve`` reports success, coal finds no clearance below the margin (beyond the check's
    tolerance) at 10× the knot density."""
    r = tcb_arm
    qa = r.neutral()
    qb = qa.copy()
    qb[:3] += np.array([0.6, -0.4, 0.5])                       # arm A only
    d = r.model.createData()
    ee = r.arm("A").ee_frame_id
    pin.framesForwardKinematics(r.model, d, qa + frac * (qb - qa))
    p = d.oMf[ee].translation.copy()
    u = np.array([np.cos(side), np.sin(side), 0.0])
    c = p + (offset + size / 2) * u
    scene = Scene("box", None, (Obstacle("box", "box", pin.SE3(np.eye(3), c), size=(size, size, size)),))
    checker = CollisionChecker(r, scene, self_collision=False)
    for q in (qa, qb):   # the given ends must clear the margin (else nothing can succeed)
        assume(checker.distances(q).min() > margin + 0.01)
    z = np.zeros(r.nj)
    prob = OptProblem(r, n_intervals=6, duration=2.0)
    prob.add_constraint(JointBoundary("start", q=qa, qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=qb, qd=z, qdd=z))
    prob.add_cost(Smoothness("jerk"))
    prob.add_constraint(CollisionAvoidance(scene, margin=margin, self_collision=False))
    prob.set_initial_straight_line(qa, qb)
    sol = prob.solve(max_iter=200)
    if sol.success:
        o = GuaranteeOptions()
        ts = np.linspace(0.0, sol.duration, 10 * (len(sol.t) - 1) + 1)
        dmin, pair, _ = checker.min_distance_along(sol.sample(ts)["q"])
        assert dmin >= margin - (o.tol + o.rel_tol * margin) - 1e-9, (dmin, pair)
    else:
        assert sol.status is not IpoptStatus.SOLVE_SUCCEEDED or sol.between_knots



# --------------------------------------------------------------------------- closed chain, knots moved
def test_closed_chain_drift_is_refined_and_knot_terms_follow(tcb_arm):
    """A closed-chain transport on 8 intervals drifts between knots (∝ h⁴); ``solve`` refines the
    grid until the chain holds densely (Pinocchio FK in ``verify``), and a position imposed at knot
    4 of 8 is imposed at the same time on the finer grid."""
    from optplan.constraints.closed_chain import project_closed_chain
    from optplan.model.kinematics import Kinematics
    from optplan.problem import ClosedChain, FramePose

    r = tcb_arm
    rng = np.random.default_rng(3)
    qa = r.random_joints(rng) * 0.4
    cc = ClosedChain.from_configuration(r, qa)
    qb = project_closed_chain(r, qa + rng.normal(size=14) * 0.15, cc).q
    qm = project_closed_chain(r, (qa + qb) / 2 + rng.normal(size=14) * 0.02, cc).q
    target = Kinematics(r).frame_placements(qm, [r.arm("A").ee_frame])[0]
    z = np.zeros(14)

    def problem():
        # the knot transcription: its closed chain drifts ∝ h⁴ between knots (the case refined here)
        prob = OptProblem(r, n_intervals=8, duration=4.0, transcription="knots")
        prob.add_constraint(JointBoundary("start", q=qa, qd=z, qdd=z))
        prob.add_constraint(JointBoundary("end", q=qb, qd=z, qdd=z))
        prob.add_constraint(cc)
        fp = prob.add_constraint(FramePose(r.arm("A").ee_frame, target, at=4, position_only=True))
        prob.add_cost(Smoothness("jerk"))
        prob.set_initial_straight_line(qa, qb)
        return prob, fp

    o = GuaranteeOptions(tol=1e-5, rel_tol=0.0)   # the closed chain to 1e-5 m / rad per row
    prob, _ = problem()
    knots = prob.solve_knots(tol=1e-9)
    assert knots.success
    assert verify(r, knots, closed_chain=cc).max_closed_chain_residual > 2 * o.tol   # drifts between knots
    prob, fp = problem()
    sol = prob.solve(tol=1e-9, guarantees=o)
    assert sol.success, (sol.status, sol.between_knots[:2])
    assert prob.N > 8 and "refine" in [a.label for a in sol.attempts]
    assert verify(r, sol, closed_chain=cc).max_closed_chain_residual <= 2 * o.tol     # |rows| ≤ tol each
    assert prob.terms[fp.name].term.at == prob.N // 2                             # knot 4 of 8 → same time
    k = int(np.argmin(np.abs(sol.t - 2.0)))
    M = Kinematics(r).frame_placements(sol.q[k], [r.arm("A").ee_frame])[0]
    np.testing.assert_allclose(M.translation, target.translation, atol=1e-6)
    assert sol.value(fp).shape == (1, 3)                                          # the user's handle


def test_dense_check_on_a_floating_robot():
    """Torque and velocity limits of a free-floating robot evaluated between knots: the sampled
    torque rows are Pinocchio's floating-base torques (zero base wrench, zero momentum)."""
    from optplan.problem import JointTorqueLimits, JointVelocityLimits
    from optplan.problem.dynamics_terms import joint_torques_numeric

    r = RobotModel.from_name("eba_ffsr")
    q0 = r.joints_of(r.neutral())
    q1 = q0.copy()
    q1[:3] += 0.6
    z = np.zeros(r.nj)
    prob = OptProblem(r, n_intervals=3, duration=2.0, n_sub=1)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=q1, qd=z, qdd=z))
    prob.add_constraint(JointVelocityLimits(limit=10.0))
    ht = prob.add_constraint(JointTorqueLimits(limit=1e4))
    prob.add_cost(Smoothness("jerk"))
    prob.set_initial_straight_line(q0, q1)
    sol = prob.solve_knots()
    assert sol.success
    ts = np.linspace(0.0, 2.0, 41)
    s = sol.sample(ts)
    tau = np.array([joint_torques_numeric(r, *x) for x in zip(s["q"], s["qd"], s["qdd"])])
    np.testing.assert_allclose(sol.sample(ts, ht), tau, rtol=1e-9, atol=1e-9)
    assert check_between_knots(prob, sol) == []


def test_bspline_core_solutions_are_checked_and_refined_between_knots(tcb_arm):
    """On the B-spline core (the default), ``solve`` checks the closed chain densely too: a coarse
    grid whose chain drifts between knots is refined (N grows) until it holds, or reported."""
    from optplan.constraints.closed_chain import project_closed_chain
    from optplan.problem import ClosedChain

    r = tcb_arm
    rng = np.random.default_rng(3)
    qa = r.random_joints(rng) * 0.4
    cc = ClosedChain.from_configuration(r, qa)
    qb = project_closed_chain(r, qa + rng.normal(size=14) * 0.15, cc).q
    z = np.zeros(14)
    prob = OptProblem(r, n_intervals=6, duration=4.0)
    prob.add_constraint(JointBoundary("start", q=qa, qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=qb, qd=z, qdd=z))
    prob.add_constraint(cc)
    prob.add_cost(Smoothness("jerk"))
    prob.set_initial_straight_line(qa, qb)
    assert prob._mode() == "bspline"
    o = GuaranteeOptions(tol=1e-5, rel_tol=0.0)
    knots = prob.solve(guarantees=False)
    drift = verify(r, knots, closed_chain=cc).max_closed_chain_residual
    sol = prob.solve(guarantees=o)
    res = verify(r, sol, closed_chain=cc).max_closed_chain_residual
    assert knots.success and drift > 2 * o.tol          # the coarse grid drifts between knots
    assert sol.success, (sol.status, sol.between_knots[:2])
    assert prob.N > 6 and "refine" in [a.label for a in sol.attempts]
    assert res <= 2 * o.tol, (drift, res)
