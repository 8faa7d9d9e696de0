"""The floating-base B-spline NLP (optplan.problem.floating_segment): its kernels against
Pinocchio's numeric algorithms, its assembled derivatives against finite differences, and the
integrated base attitude of a solved restoration against an independent adaptive integration
(scipy solve_ivp on Pinocchio's centroidal map)."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan import RobotModel
from optplan.bench.restoration import ivp_attitude, quat_angle
from optplan.papers import eba
from optplan.problem import ClosedChain
from optplan.problem.floating_segment import FloatingKernels, FloatingSegmentSpec, FloatingSplineProblem, spline_basis


@pytest.fixture(scope="module")
def robot():
    return RobotModel.from_name("eba_ffsr")


@pytest.fixture(scope="module")
def kernels(robot):
    return FloatingKernels.of(robot)


def _random_state(robot, rng):
    q = rng.uniform(-np.pi, np.pi, robot.nj)
    return q, rng.normal(size=robot.nj)


def _pin_base_rate(robot, q, qd):
    """Base angular velocity (base frame) at zero momentum, from Pinocchio's centroidal map (the
    full 6 × 6 base block, base at identity)."""
    data = robot.model.createData()
    Ag = pin.computeCentroidalMap(robot.model, data, np.r_[np.zeros(6), 1.0, q])
    return np.linalg.solve(Ag[:, :6], -Ag[:, 6:] @ qd)[3:]


def test_momentum_kernel_matches_pinocchio(robot, kernels):
    rng = np.random.default_rng(11)
    f = kernels.momentum()
    nj = robot.nj
    for _ in range(5):
        q, qd = _random_state(robot, rng)
        # the kernel is linear in ω': A_ω = its value at the unit vectors, minus the offset
        r0 = np.asarray(f(np.r_[q, qd, np.zeros(3)])).ravel()
        Aw = np.column_stack([np.asarray(f(np.r_[q, qd, e])).ravel() - r0 for e in np.eye(3)])
        w = np.linalg.solve(Aw, -r0)
        assert np.allclose(w, _pin_base_rate(robot, q, qd), rtol=1e-9, atol=1e-11)
        # and it is the angular momentum about the CoM: Pinocchio's, for the base twist [0; ω]
        data = robot.model.createData()
        qf = np.r_[np.zeros(6), 1.0, q]
        h = pin.computeCentroidalMomentum(robot.model, data, qf, np.r_[np.zeros(3), w + 0.1, qd])
        assert np.allclose(np.asarray(f(np.r_[q, qd, w + 0.1])).ravel(), h.angular, atol=1e-9)
        assert nj == 14


def test_closed_chain_kernel_matches_pinocchio(robot, kernels):
    rng = np.random.default_rng(12)
    q0 = rng.uniform(-1, 1, robot.nj)
    cc = ClosedChain.from_configuration(robot, robot.configuration(q0), "A", "B")
    f = kernels.closed_chain(cc)
    assert np.allclose(np.asarray(f(q0)).ravel(), np.r_[np.zeros(6), 3.0], atol=1e-12)
    data = robot.model.createData()
    fa, fb = robot.arm("A").ee_frame_id, robot.arm("B").ee_frame_id
    for _ in range(3):
        q = q0 + rng.normal(scale=0.2, size=robot.nj)
        pin.framesForwardKinematics(robot.model, data, np.r_[rng.normal(size=3), pin.Quaternion(
            pin.exp3(rng.normal(size=3))).coeffs(), q])  # any base pose: the relative pose ignores it
        rel = data.oMf[fa].actInv(data.oMf[fb])
        E = cc.relative.rotation.T @ rel.rotation
        ref = np.r_[rel.translation - cc.relative.translation,
                    0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]]), np.trace(E)]
        assert np.allclose(np.asarray(f(q)).ravel(), ref, atol=1e-12)


def test_attitude_step_is_rk4_of_the_exact_rotation(kernels):
    """Constant ω': the exact solution is ξ ⊗ exp(ω'/2); RK4's error is O(|ω'|⁵)."""
    rng = np.random.default_rng(13)
    for n_sub in (1, 2):
        f = kernels.attitude_step(n_sub)
        xi = pin.Quaternion(pin.exp3(rng.normal(size=3))).coeffs()
        w = rng.normal(scale=0.05, size=3)
        out = -np.asarray(f(np.r_[xi, np.zeros(4), np.tile(w, 2 * n_sub + 1)])).ravel()
        exact = (pin.Quaternion(xi[3], *xi[:3]) * pin.Quaternion(pin.exp3(w))).coeffs()
        assert np.linalg.norm(out - exact) < 1e-9 / n_sub**4
        assert abs(np.linalg.norm(out) - 1) < 1e-14


def test_spline_basis_matches_the_knot_maps():
    b0, d0 = spline_basis(0.0)
    b1, d1 = spline_basis(1.0)
    assert np.allclose(b0, [1 / 6, 4 / 6, 1 / 6, 0]) and np.allclose(d0, [-0.5, 0, 0.5, 0])
    assert np.allclose(b1, [0, 1 / 6, 4 / 6, 1 / 6]) and np.allclose(d1, [0, -0.5, 0, 0.5])
    for u in (0.2, 0.5, 0.9):  # partition of unity, derivative of the basis
        b, d = spline_basis(u)
        bp, _ = spline_basis(u + 1e-6)
        assert abs(b.sum() - 1) < 1e-15 and abs(d.sum()) < 1e-15
        assert np.allclose((bp - b) / 1e-6, d, atol=1e-5)


@pytest.fixture(scope="module")
def small_problem(robot):
    sc = eba.end_constrained_scenario(robot)
    cc = ClosedChain.from_configuration(robot, robot.configuration(sc.theta0), "A", "B")
    N = 6
    prob = FloatingSplineProblem(robot, FloatingSegmentSpec(N, 20.0, sc.theta0, sc.thetaf, closed_chain=cc))
    from optplan.papers.eba.baselines import closed_chain_reference

    prob.set_initial(closed_chain_reference(robot, sc, N, 20.0)[1])
    return prob


def test_assembled_derivatives_match_finite_differences(small_problem):
    """The builder's NLP (the OptProblem's B-spline core: momentum, RK4 attitude, closed chain,
    end attitude, jerk): the assembled Jacobian and Lagrangian Hessian against central differences."""
    import casadi as ca

    sp = small_problem.problem._spline
    sp.prepare()
    core = sp.core
    b = core.structure(sp.row_families(), bool(sp.pbounds), False)
    rng = np.random.default_rng(14)
    nx = core.nx
    x = sp.guess(20.0) + rng.normal(scale=1e-2, size=nx)
    p = sp._pvec(20.0, sp._com0(small_problem.spec.q_start), 1.0)
    g0, J = (np.asarray(ca_dense(v)) for v in b["derivs"]["jac_g"](x, p))
    gfun = b["gfun"]
    eps = 1e-6
    Jfd = np.zeros_like(J)
    for i in range(nx):
        e = np.zeros(nx)
        e[i] = eps
        Jfd[:, i] = (np.asarray(gfun(x + e, p)).ravel() - np.asarray(gfun(x - e, p)).ravel()) / (2 * eps)
    assert np.abs(J - Jfd).max() < 1e-6 * max(1.0, np.abs(J).max())
    # Hessian of the Lagrangian: finite differences of ∇(σ f + λᵀ g)
    lam = rng.normal(size=g0.size)
    sigma = 0.7
    xs = b["nlp"]["x"]
    L = sigma * b["nlp"]["f"] + ca.dot(ca.DM(lam), b["nlp"]["g"])
    grad = ca.Function("gradL", [xs, b["nlp"]["p"]], [ca.gradient(L, xs)])
    H = ca_dense(b["derivs"]["hess_lag"](x, p, sigma, lam))
    H = np.triu(H) + np.triu(H, 1).T
    Hfd = np.zeros_like(H)
    for i in range(nx):
        e = np.zeros(nx)
        e[i] = eps
        Hfd[:, i] = (np.asarray(grad(x + e, p)).ravel() - np.asarray(grad(x - e, p)).ravel()) / (2 * eps)
    assert np.abs(H - Hfd).max() < 1e-5 * max(1.0, np.abs(H).max())


def ca_dense(M):
    import casadi as ca

    return np.asarray(ca.DM(M).full())


def test_restoration_attitude_against_an_independent_integration(robot):
    """Free-end restoration N = 20: the NLP's knot attitudes agree with the adaptive integration
    to the stated RK4 bound (≤ 1e-6 rad at h = 1 s), and the end attitude is restored."""
    res = eba.run_nlp(robot, eba.free_end_scenario())
    assert res.success, res.message
    sol = res.raw
    ref = ivp_attitude(robot, sol)
    err = max(quat_angle(a, b) for a, b in zip(sol.base_quat, ref))
    assert err <= 1e-6
    assert quat_angle(ref[-1], [0, 0, 0, 1.0]) <= 1e-6  # independent end-attitude error
    assert res.info["transcription"] == "bspline"
    assert res.info["boundary_velocity_max"] <= 1e-12  # rest at both ends by construction


def test_bad_input_is_refused(robot):
    sc = eba.free_end_scenario()
    with pytest.raises(ValueError, match="n_intervals"):
        FloatingSplineProblem(robot, FloatingSegmentSpec(3, 20.0, sc.theta0, sc.thetaf))
    with pytest.raises(ValueError, match="end_attitude"):
        FloatingSplineProblem(robot, FloatingSegmentSpec(8, 20.0, sc.theta0, sc.thetaf, end_attitude=np.ones((3, 3))))
    with pytest.raises(ValueError, match="n_sub"):
        FloatingSplineProblem(robot, FloatingSegmentSpec(8, 20.0, sc.theta0, sc.thetaf, n_sub=0))
    with pytest.raises(ValueError, match="fixed base"):
        FloatingSplineProblem(RobotModel.from_name("tcbirrt_dual_arm"), FloatingSegmentSpec(8, 1.0, np.zeros(14),
                                                                                              np.zeros(14)))
    prob = FloatingSplineProblem(robot, FloatingSegmentSpec(8, 20.0, sc.theta0, sc.thetaf))
    with pytest.raises(ValueError, match="initial guess"):
        prob.solve()
    with pytest.raises(ValueError, match="expected"):
        prob.set_initial(np.zeros((3, robot.nj)))
    with pytest.raises(ValueError, match="transcription"):
        eba.NLPOptions(transcription="collocation")
    with pytest.raises(ValueError, match="coarse_intervals"):
        eba.NLPOptions(coarse_intervals=2)
    with pytest.raises(ValueError, match="compile_kernels"):
        eba.NLPOptions(compile_kernels="yes")
    with pytest.raises(ValueError, match="max_wall_time"):
        prob.solve(max_wall_time=0.0)


def test_the_time_cap_ends_in_a_status(robot):
    res = eba.run_nlp(robot, eba.free_end_scenario(), eba.NLPOptions.free_end(max_wall_time=1e-3))
    assert not res.success and "WallTime" in res.message
    assert res.info["ipopt_status"] == "Maximum_WallTime_Exceeded"


def test_knots_transcription_is_kept_as_an_option(robot):
    o = eba.NLPOptions.free_end(n_intervals=6, transcription="knots")
    prob, cc = eba.build_nlp(robot, eba.free_end_scenario(), o)
    from optplan.problem import OptProblem

    assert isinstance(prob, OptProblem) and cc is None


def test_compiled_kernels_equal_the_symbolic_ones(kernels, tmp_path):
    """The C-compiled form (a small kernel, -O0 to keep the test quick) evaluates as the SX one."""
    import shutil

    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler")
    f = kernels.attitude_step(1)
    _, h = kernels.local_derivatives(f)
    hc = kernels.compiled(h, opt="-O0")
    assert hc is not h and hc.name() == h.name()
    rng = np.random.default_rng(15)
    z, lam = rng.normal(size=h.size1_in(0)), rng.normal(size=4)
    assert np.allclose(np.asarray(hc(z, lam).full()), np.asarray(h(z, lam).full()), rtol=1e-12, atol=1e-13)
    assert kernels.compiled(h, opt="-O0") is hc  # loaded once


def test_a_given_end_attitude_is_reached_and_costs_are_exact(robot):
    """A non-identity end attitude (0.5° about a tilted axis) and the acceleration cost: the
    independent simulator ends at the target, the reported cost equals a dense quadrature of the
    sampled trajectory, and a second problem of the same shape reuses the built NLP."""
    from optplan import simulate_base

    sc = eba.free_end_scenario()
    R_t = pin.exp3(np.deg2rad(0.5) * np.array([0.6, 0.0, 0.8]))
    N = 12
    spec = FloatingSegmentSpec(N, 20.0, sc.theta0, sc.thetaf, end_attitude=R_t, smoothness="acceleration")
    s = np.linspace(0, 1, N + 1)
    Q = sc.theta0 + (10 * s**3 - 15 * s**4 + 6 * s**5)[:, None] * (sc.thetaf - sc.theta0)
    prob = FloatingSplineProblem(robot, spec)
    prob.set_initial(Q)
    sol = prob.solve()
    assert sol.success, sol.status
    t = np.linspace(0.0, 20.0, 40 * N + 1)
    smp = sol.sample(t)
    sim = simulate_base(robot, (t, smp["q"], smp["qd"]), t, substeps=4)
    # RK4 at h = 1.67 s: the stated bound ≈ 2.2e-7 rad · (h / 1 s)⁴ ≈ 2e-6 rad (docs/eba.md)
    assert np.linalg.norm(pin.log3(R_t.T @ sim.final_base.rotation)) < 1e-5
    qdd2 = np.sum(smp["qdd"] ** 2, axis=1)  # piecewise quadratic: Simpson on each sub-interval is exact
    dt = t[1] - t[0]
    mid = np.sum(sol.sample(t[:-1] + dt / 2)["qdd"] ** 2, axis=1)
    integral = float(np.sum(dt / 6 * (qdd2[:-1] + 4 * mid + qdd2[1:])))
    assert sol.cost == pytest.approx(integral, rel=1e-9)
    again = FloatingSplineProblem(robot, spec)  # same structure: no build
    again.set_initial(Q)
    sol2 = again.solve()
    assert sol2.setup_time < 0.5 * sol.setup_time and sol2.cost == pytest.approx(sol.cost, rel=1e-9)
