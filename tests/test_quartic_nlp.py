"""Tests of optplan.problem.quartic: quartic-spline smoothing as an IPOPT NLP."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from optplan.geometry.splines import PiecewisePolynomial, quartic_spline
from optplan.problem.quartic import QuarticSmoothingResult, smooth_quartic

L1, L2 = 1.0, 0.7  # planar 2-link arm [m]
INFEASIBLE = {"Infeasible_Problem_Detected", "Restoration_Failed"}


def two_link_ee_velocity() -> ca.Function:
    """(q (2,), qdot (2,)) -> planar end-effector linear velocity (3,) [m/s], built from the FK."""
    q, qd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2)
    p = ca.vertcat(L1 * ca.cos(q[0]) + L2 * ca.cos(q[0] + q[1]), L1 * ca.sin(q[0]) + L2 * ca.sin(q[0] + q[1]), 0)
    return ca.Function("ee_velocity", [q, qd], [ca.jacobian(p, q) @ qd])


def two_link_fk(q: np.ndarray) -> np.ndarray:
    """Independent numpy forward kinematics, (..., 2) -> (..., 2) [m]."""
    return np.stack([L1 * np.cos(q[..., 0]) + L2 * np.cos(q[..., 0] + q[..., 1]),
                     L1 * np.sin(q[..., 0]) + L2 * np.sin(q[..., 0] + q[..., 1])], axis=-1)


def per_segment_times(pp: PiecewisePolynomial, k: int) -> np.ndarray:
    """k uniformly spaced times in every segment, both ends included."""
    frac = np.linspace(0.0, 1.0, k)
    return (pp.breakpoints[:-1, None] + frac[None, :] * pp.durations[:, None]).ravel()


def assert_eq11(pp: PiecewisePolynomial, waypoints: np.ndarray, v0=0.0, a0=0.0, vf=0.0, tol=1e-7):
    """C0 at all waypoints, C1-C3 from both neighbouring segments' coefficients, boundary conditions."""
    m, h = pp.n_segments, pp.durations
    np.testing.assert_allclose(pp(pp.breakpoints), waypoints, atol=tol)
    for k in (0, 1, 2, 3):
        d = pp.derivative(k).coefficients
        left = np.array([sum(d[i, p] * h[i] ** p for p in range(d.shape[1])) for i in range(m)])  # segment ends
        right = d[:, 0]                                                                           # segment starts
        scale = 1.0 + np.abs(right).max()
        np.testing.assert_allclose(left[:-1], right[1:], atol=tol * scale, err_msg=f"C{k}")
        if k == 0:
            np.testing.assert_allclose(left[-1], waypoints[-1], atol=tol)
    np.testing.assert_allclose(pp(pp.t0, 1), np.broadcast_to(v0, (pp.dim,)), atol=tol)
    np.testing.assert_allclose(pp(pp.t0, 2), np.broadcast_to(a0, (pp.dim,)), atol=tol)
    np.testing.assert_allclose(pp(pp.tf, 1), np.broadcast_to(vf, (pp.dim,)), atol=tol)


@pytest.fixture
def problem():
    rng = np.random.default_rng(7)
    m, n = 6, 3
    times = np.concatenate([[0.5], rng.uniform(0.5, 1.5, m)]).cumsum()
    waypoints = np.cumsum(rng.normal(scale=0.4, size=(m + 1, n)), axis=0)
    return times, waypoints, dict(v0=rng.normal(scale=0.1, size=n), a0=0.05, vf=-0.1)


# ----------------------------------------------------------------------------- (1) fixed durations
@pytest.mark.parametrize("cost", ["jerk", "acceleration"])
@pytest.mark.parametrize("limits", [False, True])
def test_fixed_durations_equal_the_linear_solve(problem, cost, limits):
    times, waypoints, bc = problem
    ref = quartic_spline(times, waypoints, **bc)
    kw = {}
    if limits:  # present but inactive
        kw = dict(qdot_max=2.0 * ref.max_abs(1), qddot_max=2.0 * ref.max_abs(2) + 1.0)
    res = smooth_quartic(times, waypoints, cost=cost, **bc, **kw)
    assert isinstance(res, QuarticSmoothingResult)
    assert res.success and res.status == "Solve_Succeeded"
    np.testing.assert_allclose(res.spline.coefficients, ref.coefficients, rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.spline.breakpoints, times)
    np.testing.assert_allclose(res.durations, np.diff(times))
    assert res.max_constraint_violation < 1e-8
    assert res.iterations >= 0 and res.wall_time > 0


def test_durations_instead_of_times(problem):
    times, waypoints, bc = problem
    res = smooth_quartic(np.diff(times), waypoints, **bc)
    ref = quartic_spline(times - times[0], waypoints, **bc)
    assert res.success and res.spline.t0 == 0.0
    np.testing.assert_allclose(res.spline.coefficients, ref.coefficients, atol=1e-8)


# ----------------------------------------------------------------------------- (2) infeasible
def test_fixed_durations_velocity_limit_too_low_is_infeasible(problem):
    times, waypoints, bc = problem
    needed = quartic_spline(times, waypoints, **bc).max_abs(1)
    res = smooth_quartic(times, waypoints, qdot_max=0.7 * needed, **bc)
    assert not res.success
    assert res.status in INFEASIBLE
    assert isinstance(res.spline, PiecewisePolynomial)
    assert res.max_constraint_violation > 1e-3


# ----------------------------------------------------------------------------- (3) free durations
def test_free_durations_respect_limits_and_continuity():
    rng = np.random.default_rng(11)
    m, n = 20, 3
    waypoints = np.cumsum(rng.normal(scale=0.3, size=(m + 1, n)), axis=0)
    vmax, amax = np.array([1.0, 0.8, 1.2]), 2.0
    res = smooth_quartic(np.full(m, 0.5), waypoints, qdot_max=vmax, qddot_max=amax, free_durations=True)
    print(f"\nfree-duration NLP m={m} n={n}: {res.wall_time:.2f} s, {res.iterations} iterations, "
          f"{res.refinements} refinements, T = {res.durations.sum():.3f} s")
    assert res.success, res.status
    pp = res.spline
    assert np.all(res.durations >= 1e-3)
    t = per_segment_times(pp, 50)
    assert np.all(np.abs(pp(t, 1)) <= vmax + 1e-6)
    assert np.all(np.abs(pp(t, 2)) <= amax + 1e-6)
    assert_eq11(pp, waypoints)
    # time-optimal-ish: some limit is active
    ratio = max((pp.max_abs(1) / vmax).max(), (pp.max_abs(2) / amax).max())
    assert ratio > 1.0 - 1e-4
    assert res.max_constraint_violation < 1e-6


def test_free_durations_with_boundary_velocities(problem):
    times, waypoints, bc = problem
    res = smooth_quartic(times, waypoints, qdot_max=1.5, qddot_max=3.0, free_durations=True, **bc)
    assert res.success, res.status
    assert res.spline.t0 == times[0]
    assert_eq11(res.spline, waypoints, **bc)
    t = per_segment_times(res.spline, 50)
    assert np.all(np.abs(res.spline(t, 1)) <= 1.5 + 1e-6)


def test_single_segment_fixed_and_free():
    x = np.array([[0.0, 1.0], [1.0, -1.0]])
    fixed = smooth_quartic([0.0, 2.0], x, qdot_max=5.0)
    assert fixed.success
    np.testing.assert_allclose(fixed.spline.coefficients, quartic_spline([0.0, 2.0], x).coefficients, atol=1e-8)
    free = smooth_quartic([2.0], x, qdot_max=0.5, free_durations=True)
    assert free.success, free.status
    # rest-to-rest with free final acceleration: x = x0 + dx (4 s^3 - 3 s^4), peak speed 16/9 |dx| / T
    assert free.durations[0] == pytest.approx(16 / 9 * 2.0 / 0.5, rel=1e-6)
    assert_eq11(free.spline, x)


def test_without_refinement_limits_hold_at_the_samples():
    rng = np.random.default_rng(3)
    waypoints = np.cumsum(rng.normal(scale=0.4, size=(9, 2)), axis=0)
    res = smooth_quartic(np.ones(8), waypoints, qdot_max=1.0, free_durations=True, refine=False,
                         samples_per_segment=5)
    assert res.success and res.refinements == 0 and res.stretch == 1.0
    t = per_segment_times(res.spline, 5)
    assert np.all(np.abs(res.spline(t, 1)) <= 1.0 + 1e-6)
    assert_eq11(res.spline, waypoints)


# ----------------------------------------------------------------------------- (4) end-effector speed
def test_end_effector_speed_limit_two_link_arm():
    rng = np.random.default_rng(5)
    m = 6
    waypoints = np.cumsum(rng.normal(scale=0.5, size=(m + 1, 2)), axis=0)
    vmax_ee = 0.5
    res = smooth_quartic(np.ones(m), waypoints, ee_velocity=two_link_ee_velocity(), ee_speed_max=vmax_ee,
                         free_durations=True)
    assert res.success, res.status
    pp = res.spline
    assert_eq11(pp, waypoints)
    # independent check: numpy FK + central finite differences, 200 points per segment
    t = per_segment_times(pp, 200)
    t = np.clip(t, pp.t0 + 1e-5, pp.tf - 1e-5)
    dt = 1e-6
    v_fd = (two_link_fk(pp(t + dt)) - two_link_fk(pp(t - dt))) / (2 * dt)
    speed = np.linalg.norm(v_fd, axis=1)
    assert speed.max() <= vmax_ee + 1e-6
    assert speed.max() >= vmax_ee * (1 - 1e-3)  # the limit is what sets the duration


def test_end_effector_speed_with_mx_function_and_row_inputs(problem):
    _, waypoints, _ = problem
    fun = two_link_ee_velocity()
    q, qd = ca.MX.sym("q", 1, 2), ca.MX.sym("qd", 1, 2)
    mx_fun = ca.Function("ee_mx", [q, qd], [fun(q.T, qd.T)])
    res = smooth_quartic(np.ones(waypoints.shape[0] - 1), waypoints[:, :2], ee_velocity=mx_fun,
                         ee_speed_max=0.8, qdot_max=[np.inf, 1.0], free_durations=True)
    assert res.success, res.status
    t = per_segment_times(res.spline, 50)
    assert np.all(np.abs(res.spline(t, 1)[:, 1]) <= 1.0 + 1e-6)


# ----------------------------------------------------------------------------- failures never raise / print
def test_iteration_limit_is_a_status_not_an_exception(problem, capfd):
    times, waypoints, bc = problem
    res = smooth_quartic(times, waypoints, qdot_max=1.0, free_durations=True, ipopt_options={"max_iter": 1}, **bc)
    assert not res.success
    assert res.status == "Maximum_Iterations_Exceeded"
    assert isinstance(res.spline, PiecewisePolynomial) and res.durations.shape == (6,)
    out, err = capfd.readouterr()
    assert out == ""


def test_silent_by_default(problem, capfd):
    times, waypoints, bc = problem
    smooth_quartic(times, waypoints, qdot_max=10.0, free_durations=True, **bc)
    out, _ = capfd.readouterr()
    assert out == ""


# ----------------------------------------------------------------------------- input validation
def test_bad_inputs_raise(problem):
    times, waypoints, bc = problem
    with pytest.raises(ValueError, match="times_or_durations.*7 times or 6 durations"):
        smooth_quartic(times[:-2], waypoints)
    with pytest.raises(ValueError, match="strictly increasing"):
        smooth_quartic(times[::-1], waypoints)
    with pytest.raises(ValueError, match="ee_velocity and ee_speed_max"):
        smooth_quartic(times, waypoints, ee_speed_max=1.0)
    with pytest.raises(TypeError, match="casadi.Function"):
        smooth_quartic(times, waypoints, ee_velocity=lambda q, qd: q, ee_speed_max=1.0)
    with pytest.raises(ValueError, match="input 0 must have 3 entries"):
        smooth_quartic(times, waypoints, ee_velocity=two_link_ee_velocity(), ee_speed_max=1.0)
    with pytest.raises(ValueError, match="qdot_max"):
        smooth_quartic(times, waypoints, qdot_max=[1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="cost"):
        smooth_quartic(times, waypoints, cost="snap")
    with pytest.raises(ValueError, match="waypoints.*finite"):
        smooth_quartic(times, np.full_like(waypoints, np.nan))
    with pytest.raises(ValueError, match="samples_per_segment"):
        smooth_quartic(times, waypoints, samples_per_segment=1)


# ----------------------------------------------------------------------------- end-effector acceleration
def two_link_ee_acceleration() -> ca.Function:
    """(q, qdot, qddot) -> planar end-effector linear acceleration J q̈ + J̇ q̇ [m/s²]."""
    q, qd, qdd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2)
    p = ca.vertcat(L1 * ca.cos(q[0]) + L2 * ca.cos(q[0] + q[1]), L1 * ca.sin(q[0]) + L2 * ca.sin(q[0] + q[1]), 0)
    J = ca.jacobian(p, q)
    v = J @ qd
    return ca.Function("ee_acc", [q, qd, qdd], [J @ qdd + ca.jacobian(v, q) @ qd])


def test_end_effector_acceleration_limit_two_link_arm():
    rng = np.random.default_rng(6)
    m = 5
    waypoints = np.cumsum(rng.normal(scale=0.5, size=(m + 1, 2)), axis=0)
    amax_ee, S = 0.4, 12
    res = smooth_quartic(np.ones(m), waypoints, ee_acceleration=two_link_ee_acceleration(), ee_accel_max=amax_ee,
                         free_durations=True, samples_per_segment=S)
    assert res.success, res.status
    pp = res.spline
    assert_eq11(pp, waypoints)
    # independent check at the constrained sample points: numpy FK + second central differences
    t = np.clip(per_segment_times(pp, S), pp.t0 + 1e-4, pp.tf - 1e-4)
    dt = 1e-4
    a_fd = (two_link_fk(pp(t + dt)) - 2 * two_link_fk(pp(t)) + two_link_fk(pp(t - dt))) / dt**2
    acc = np.linalg.norm(a_fd, axis=1)
    assert acc.max() <= amax_ee * (1 + 1e-3)
    assert acc.max() >= amax_ee * 0.9  # the limit is what sets the duration


def test_end_effector_acceleration_needs_its_limit():
    with pytest.raises(ValueError, match="ee_accel_max"):
        smooth_quartic([0.0, 1.0, 2.0], np.zeros((3, 2)), ee_acceleration=two_link_ee_acceleration())


def test_quartic_smoothing_on_a_robot_arm_with_end_effector_speed_limit(tcb):
    """The Spline-RRT* paper's smoothing on real joint waypoints of tcbirrt_dual_arm: EE speed of arm A ≤ 0.1 m/s
    (the paper's limit), checked with Pinocchio's frame velocity (independent of CasADi)."""
    import pinocchio as pin

    from optplan.model.symbolic import SymbolicKinematics

    rng = np.random.default_rng(11)
    q0 = tcb.random_joints(rng) * 0.3
    waypoints = q0 + np.cumsum(rng.normal(scale=0.05, size=(5, tcb.nj)), axis=0)
    fv = SymbolicKinematics(tcb).ee_velocity_function("A")
    res = smooth_quartic(np.ones(4), waypoints, ee_velocity=fv, ee_speed_max=0.1, free_durations=True)
    assert res.success, res.status
    pp = res.spline
    data = tcb.model.createData()
    fid = tcb.arm("A").ee_frame_id
    speeds = []
    for t in per_segment_times(pp, 40):
        q, v = pp(t), pp(t, 1)
        pin.forwardKinematics(tcb.model, data, q, v)
        speeds.append(np.linalg.norm(pin.getFrameVelocity(tcb.model, data, fid,
                                                          pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).linear))
    assert max(speeds) <= 0.1 + 1e-6
    assert max(speeds) >= 0.1 * 0.99
