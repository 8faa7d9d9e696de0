"""OptProblem.solve end to end, against closed-form optima and independent re-evaluation.

(a) minimum jerk between rest configurations → the quintic 10s³−15s⁴+6s⁵ (error O(N⁻²));
    minimum acceleration with zero boundary velocities → the cubic 3s²−2s³ (exact);
(b) infeasible problems → a failed Solution with an infeasibility status, never an exception;
(c) Solution save/load (npz, json) round trips; ``sample`` is the exact piecewise cubic
    (checked against scipy's cubic Hermite spline of the knot values and rates);
(d) warm starts; ``set_initial`` on a non-uniform time grid;
(e) free final time with a Duration cost under velocity/acceleration limits;
(f) free-floating eba: attitude restoration, checked by verify()'s independent simulator.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.interpolate import CubicHermiteSpline

from optplan.model.kinematics import Kinematics
from optplan.problem import (
    BaseAttitude,
    ClosedChain,
    Duration,
    FramePose,
    IpoptStatus,
    JointAccelerationLimits,
    JointBoundary,
    JointPositionLimits,
    JointVelocityLimits,
    OptProblem,
    Smoothness,
    Solution,
)
from optplan.verification import verify

DEG = np.pi / 180
Z = np.zeros(14)


def unshadow_com0(prob: OptProblem) -> OptProblem:
    """Work around problem.py's ``self._com0 = None`` shadowing the ``_com0`` method (see
    tests/test_problem_terms.py::test_floating_problem_builds); a no-op once fixed."""
    if vars(prob).get("_com0", 0) is None:
        del prob._com0
    return prob


@pytest.fixture(scope="module")
def ends():
    rng = np.random.default_rng(0)
    return rng.uniform(-1, 1, 14), rng.uniform(-1, 1, 14)


def rest_to_rest(robot, qa, qb, N, order, T=3.0, zero_acc=True):
    p = OptProblem(robot, n_intervals=N, duration=T)
    extra = {"qdd": Z} if zero_acc else {}
    p.add_constraint(JointBoundary("start", q=qa, qd=Z, **extra))
    p.add_constraint(JointBoundary("end", q=qb, qd=Z, **extra))
    p.add_cost(Smoothness(order))
    return p


# --------------------------------------------------------------------------- (a) closed forms
def _quintic_error(tcb, qa, qb, N, T=3.0):
    p = rest_to_rest(tcb, qa, qb, N, "jerk", T)
    p.set_initial(q=np.vstack([qa, (qa + qb) / 2 + 0.3, qb]))   # not the answer
    sol = p.solve()
    assert sol.success, sol.status
    t = np.linspace(0, T, 1201)
    s = t / T
    ref = qa + (qb - qa) * (10 * s**3 - 15 * s**4 + 6 * s**5)[:, None]
    return np.abs(sol.sample(t)["q"] - ref).max() / np.abs(qb - qa).max(), sol


def test_minimum_jerk_converges_to_quintic(tcb, ends):
    qa, qb = ends
    e20, sol = _quintic_error(tcb, qa, qb, 20)
    e40, _ = _quintic_error(tcb, qa, qb, 40)
    print(f"quintic relative error: N=20 {e20:.3e}, N=40 {e40:.3e} (ratio {e20 / e40:.2f})")
    assert e20 < 1e-3
    assert e40 * 3 <= e20
    # boundary conditions hold exactly, and the reported cost is ∫|j|² (knot jerks)
    np.testing.assert_allclose(sol.q[[0, -1]], [qa, qb], atol=1e-9)
    np.testing.assert_allclose(sol.qd[[0, -1]], 0, atol=1e-9)
    np.testing.assert_allclose(sol.qdd[[0, -1]], 0, atol=1e-9)
    h = sol.duration / 20
    assert sol.terms["smoothness"] == pytest.approx(h * np.sum(sol.jerk**2), rel=1e-10)
    # the quintic's own cost is a lower bound of the spline-constrained optimum: 720/T⁵ Σ Δq²
    assert sol.terms["smoothness"] >= 720 / 3.0**5 * np.sum((qb - qa) ** 2) * (1 - 1e-9)


def test_minimum_acceleration_is_the_cubic(tcb, ends):
    qa, qb = ends
    T = 3.0
    for N in (5, 16):
        p = rest_to_rest(tcb, qa, qb, N, "acceleration", T, zero_acc=False)
        p.set_initial_straight_line(qa, qb)          # the quintic: not the answer
        sol = p.solve()
        assert sol.success and sol.iterations >= 1
        t = np.linspace(0, T, 777)
        s = t / T
        smp = sol.sample(t)
        np.testing.assert_allclose(smp["q"], qa + (qb - qa) * (3 * s**2 - 2 * s**3)[:, None], atol=1e-9)
        np.testing.assert_allclose(smp["qd"], (qb - qa) * (6 * s - 6 * s**2)[:, None] / T, atol=1e-9)
        np.testing.assert_allclose(sol.terms["smoothness"], 12 / T**3 * np.sum((qb - qa) ** 2), rtol=1e-9)


# --------------------------------------------------------------------------- (b) infeasible
def _infeasible(tcb, ends, kind):
    qa, qb = ends
    p = OptProblem(tcb, n_intervals=8, duration=3.0)
    if kind == "end_outside_limits":
        qbad = qb.copy()
        qbad[3] = tcb.upper[3] + 0.5
        p.add_constraint(JointBoundary("start", q=qa))
        p.add_constraint(JointBoundary("end", q=qbad))
        p.add_constraint(JointPositionLimits())
    elif kind == "contradictory_boundaries":
        p.add_constraint(JointBoundary("end", q=qb))
        p.add_constraint(JointBoundary("end", q=qb + 0.2))
    else:  # too far for the velocity limit in the time given
        p.add_constraint(JointBoundary("start", q=qa, qd=Z))
        p.add_constraint(JointBoundary("end", q=qa + 2.0, qd=Z))
        p.add_constraint(JointVelocityLimits(limit=0.1))
    p.add_cost(Smoothness("jerk"))
    p.set_initial_straight_line(qa, qb)
    return p


@pytest.mark.parametrize("kind", ["end_outside_limits", "contradictory_boundaries", "velocity_too_low"])
def test_infeasible_problem_reports_failure(tcb, ends, kind):
    sol = _infeasible(tcb, ends, kind).solve()          # must not raise
    assert isinstance(sol, Solution)
    assert not sol.success
    assert sol.status.infeasible or not sol.success
    assert sol.status in (IpoptStatus.INFEASIBLE_PROBLEM_DETECTED, IpoptStatus.RESTORATION_FAILED,
                          IpoptStatus.MAXIMUM_ITERATIONS_EXCEEDED, IpoptStatus.SEARCH_DIRECTION_BECOMES_TOO_SMALL)
    assert sol.max_constraint_violation > 1e-3
    # the violated term is named in the per-term report
    assert max(v for k, v in sol.terms.items() if k != "smoothness") == pytest.approx(sol.max_constraint_violation)
    assert sol.q.shape == (9, 14) and np.all(np.isfinite(sol.q))


# --------------------------------------------------------------------------- (c) Solution
@pytest.fixture(scope="module")
def solved(tcb, ends):
    qa, qb = ends
    p = rest_to_rest(tcb, qa, qb, 7, "jerk", T=2.5)
    p.add_constraint(JointVelocityLimits(limit=2.0))
    p.set_initial_straight_line(qa, qb)
    return p, p.solve()


def _assert_same(a: Solution, b: Solution):
    for k in ("t", "q", "qd", "qdd", "jerk", "base_quat", "base_position", "x", "lam_g"):
        va, vb = getattr(a, k), getattr(b, k)
        if va is None:
            assert vb is None, k
        else:
            assert vb.dtype == np.float64
            np.testing.assert_array_equal(va, vb, err_msg=k)
    for k in ("success", "status", "iterations", "joint_names", "terms"):
        assert getattr(a, k) == getattr(b, k), k
    for k in ("wall_time", "cost", "max_constraint_violation", "setup_time"):
        va, vb = getattr(a, k, 0.0), getattr(b, k, 0.0)
        assert (math.isnan(va) and math.isnan(vb)) or va == vb, k


@pytest.mark.parametrize("suffix", [".npz", ".json", ""])
def test_save_load_round_trip(solved, tmp_path, suffix):
    _, sol = solved
    assert sol.success
    path = sol.save(tmp_path / f"sol{suffix}")
    assert path.exists() and path.suffix in (".npz", ".json")
    back = Solution.load(path)
    _assert_same(sol, back)
    np.testing.assert_array_equal(back.sample(np.linspace(0, sol.duration, 33))["q"],
                                  sol.sample(np.linspace(0, sol.duration, 33))["q"])


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_save_load_floating_failed_solution(tmp_path, suffix, rng):
    """Hand-made Solution of a floating robot that failed: base arrays, no multipliers, NaN cost."""
    N = 3
    sol = Solution(success=False, status=IpoptStatus.INTERNAL_ERROR, iterations=-1, wall_time=0.25,
                   cost=float("nan"), max_constraint_violation=float("inf"), terms={"a": 1.5, "b": float("inf")},
                   t=np.linspace(0, 3, N + 1), q=rng.normal(size=(N + 1, 2)), qd=rng.normal(size=(N + 1, 2)),
                   qdd=rng.normal(size=(N + 1, 2)), jerk=rng.normal(size=(N, 2)), joint_names=("j1", "j2"),
                   base_quat=rng.normal(size=(N + 1, 4)), base_position=rng.normal(size=(N + 1, 3)),
                   x=rng.normal(size=40), lam_g=None)
    back = Solution.load(sol.save(tmp_path / f"f{suffix}"))
    _assert_same(sol, back)


def test_load_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.npz"):
        Solution.load(tmp_path / "nope.npz")


def test_sample_is_the_exact_piecewise_cubic(solved):
    _, sol = solved
    # knots
    smp = sol.sample(sol.t)
    np.testing.assert_allclose(smp["q"], sol.q, atol=1e-9)
    np.testing.assert_allclose(smp["qd"], sol.qd, atol=1e-9)
    np.testing.assert_allclose(smp["qdd"], sol.qdd, atol=1e-9)
    # between knots: the cubic Hermite interpolant of (q_k, q̇_k) is the unique cubic on each interval
    t = np.sort(np.random.default_rng(1).uniform(0, sol.duration, 300))
    smp = sol.sample(t)
    H = CubicHermiteSpline(sol.t, sol.q, sol.qd, axis=0)
    np.testing.assert_allclose(smp["q"], H(t), atol=1e-9)
    np.testing.assert_allclose(smp["qd"], H(t, 1), atol=1e-8)
    np.testing.assert_allclose(smp["qdd"], H(t, 2), atol=1e-7)
    # by hand, within interval k at offset tau (constant jerk)
    k, tau = 3, 0.37 * (sol.t[1] - sol.t[0])
    s1 = sol.sample(sol.t[k] + tau)
    by_hand = sol.q[k] + tau * sol.qd[k] + tau**2 / 2 * sol.qdd[k] + tau**3 / 6 * sol.jerk[k]
    np.testing.assert_allclose(s1["q"][0], by_hand, atol=1e-14)
    with pytest.raises(ValueError, match="sample"):
        sol.sample(sol.duration + 0.1)


# --------------------------------------------------------------------------- (d) initial guesses
def _closed_chain_problem(tcb, N=10, limits=False):
    rng = np.random.default_rng(3)
    qa = tcb.random_joints(rng) * 0.4
    qb = qa + rng.normal(size=14) * 0.3
    Mb = Kinematics(tcb).frame_placements(qb, [tcb.arm("A").ee_frame])[0]
    p = OptProblem(tcb, n_intervals=N, duration=5.0)
    p.add_constraint(JointBoundary("start", q=qa, qd=Z, qdd=Z))
    p.add_constraint(JointBoundary("end", qd=Z, qdd=Z))
    p.add_constraint(FramePose(tcb.arm("A").ee_frame, Mb, at="end"))
    p.add_constraint(ClosedChain.from_configuration(tcb, qa))
    if limits:
        p.add_constraint(JointVelocityLimits(limit=0.5))
    p.add_cost(Smoothness("jerk"))
    p.set_initial(q=np.vstack([qa, qa]))
    return p


def test_warm_start_reuses_the_solution(tcb):
    p = _closed_chain_problem(tcb, limits=True)
    cold = p.solve()
    assert cold.success and cold.iterations > 5
    p.set_initial(solution=cold)
    np.testing.assert_array_equal(p.initial_guess, cold.x)       # same knots: the raw vector
    warm = p.solve()
    assert warm.success
    np.testing.assert_allclose(warm.q, cold.q, atol=1e-5)
    # different knots: resampled, and it still converges to the same trajectory
    p2 = _closed_chain_problem(tcb, N=14, limits=True)
    p2.set_initial(solution=cold)
    u = p2.tp.unpack(p2.initial_guess)
    np.testing.assert_allclose(u["q"][[0, -1]], cold.q[[0, -1]], atol=1e-12)
    # on these knots (the dense check would refine past what this NLP solves: test_guarantees.py)
    assert p2.solve(guarantees=False).success


def test_warm_start_with_multipliers_is_fast_when_ipopt_is_told(tcb):
    """With IPOPT's warm_start_init_point the stored lam_g make a warm start converge at once."""
    p = _closed_chain_problem(tcb)
    cold = p.solve()
    assert cold.success and cold.iterations > 5
    p.set_initial(solution=cold)
    warm = p.solve({"warm_start_init_point": "yes"})
    assert warm.success and warm.iterations <= 3, warm.iterations


def test_warm_start_converges_in_few_iterations(tcb):
    p = _closed_chain_problem(tcb)
    cold = p.solve()
    assert cold.success and cold.iterations > 5
    p.set_initial(solution=cold)
    warm = p.solve()
    assert warm.success and warm.iterations <= 3, warm.iterations


def test_set_initial_on_a_non_uniform_grid(tcb, ends):
    """Samples of the rest-to-rest cubic at non-uniform times: the clamped spline reproduces it
    exactly, so the initial knots are the cubic's values, rates and accelerations and satisfy the
    transcription's dynamics constraints; times are shifted to start at 0."""
    qa, qb = ends
    T, N = 4.0, 9
    t = np.array([0.0, 0.13, 0.5, 1.7, 1.9, 3.2, 4.0])

    def cubic(tt, d=0):
        s = tt / T
        f = [3 * s**2 - 2 * s**3, (6 * s - 6 * s**2) / T, (6 - 12 * s) / T**2][d]
        return qa + (qb - qa) * f[:, None] if d == 0 else (qb - qa) * f[:, None]

    for offset in (0.0, 10.0):
        p = rest_to_rest(tcb, qa, qb, N, "acceleration", T, zero_acc=False)
        p.set_initial(q=cubic(t), t=t + offset)
        u = p.tp.unpack(p.initial_guess)
        tk = np.linspace(0, T, N + 1)
        np.testing.assert_allclose(u["q"], cubic(tk), atol=1e-12)
        np.testing.assert_allclose(u["qd"], cubic(tk, 1), atol=1e-12)
        np.testing.assert_allclose(u["qdd"], cubic(tk, 2), atol=1e-12)
        np.testing.assert_allclose(u["jerk"], np.tile(-12 * (qb - qa) / T**3, (N, 1)), atol=1e-11)
        g = np.array(p._build()["gfun"](p.initial_guess)).ravel()[:3 * 14 * N]   # jerk integration rows
        assert np.abs(g).max() < 1e-12
        sol = p.solve()
        assert sol.success and sol.iterations <= 1     # the guess is the optimum
    with pytest.raises(ValueError, match="increasing"):
        p.set_initial(q=cubic(t), t=t[::-1])


# --------------------------------------------------------------------------- (e) free final time
def test_free_time_duration_with_velocity_limit(tcb):
    rng = np.random.default_rng(0)
    qa = rng.uniform(-1, 1, 14)
    qb = qa + np.linspace(0.2, 1.0, 14)
    vmax, amax, bounds = 0.2, 0.5, (0.5, 100.0)
    p = OptProblem(tcb, n_intervals=20, duration=20.0, free_time=True, duration_bounds=bounds)
    p.add_constraint(JointBoundary("start", q=qa, qd=Z, qdd=Z))
    p.add_constraint(JointBoundary("end", q=qb, qd=Z, qdd=Z))
    p.add_constraint(JointVelocityLimits(limit=vmax))
    p.add_constraint(JointAccelerationLimits(limit=amax))
    dur = p.add_cost(Duration())
    p.add_cost(Smoothness("jerk"), weight=1e-4)
    p.set_initial_straight_line(qa, qb)
    sol = p.solve()
    assert sol.success, sol.status
    T = sol.duration
    assert bounds[0] < T < bounds[1]
    assert T < 10.0                                           # really shortened from 20 s
    assert sol.terms[dur.name] == pytest.approx(T, rel=1e-12)
    assert np.abs(sol.qd).max() == pytest.approx(vmax, rel=1e-5)     # the velocity limit is active
    assert np.abs(sol.qdd).max() <= amax * (1 + 1e-6)
    # independent lower bound: the joint that travels 1 rad needs T ≥ 1 / max|q̇| (dense samples)
    dense = sol.sample(np.linspace(0, T, 4001))
    assert T >= 1.0 / np.abs(dense["qd"][:, 13]).max() - 1e-9
    # and time-optimal up to the trapezoid's acceleration phases: T ≤ D/v + v/a + (slack for C2)
    assert T <= 1.0 / vmax + vmax / amax + 1.0


# --------------------------------------------------------------------------- (f) floating base
Q0 = np.r_[[-23.44, -90, 12.51, 104.8, -27.33, 66.56, -38] * 2] * DEG
QF = np.r_[[-23.44, -80, -17.49, 134.8, -12.33, 111.56, -38],
           [-23.44, -180, 47.51, 144.8, 7.67, 86.56, -38]] * DEG


def _restoration(eba, N, **solve_kw):
    p = unshadow_com0(OptProblem(eba, n_intervals=N, duration=20.0))
    p.add_constraint(JointBoundary("start", q=Q0, qd=Z, qdd=Z))
    p.add_constraint(JointBoundary("end", q=QF, qd=Z, qdd=Z))
    att = p.add_constraint(BaseAttitude(target=np.eye(3), at="end"))
    p.add_cost(Smoothness("jerk"))
    p.set_initial_straight_line(Q0, QF)
    return p, att, p.solve(**solve_kw)


def _check_restoration(eba, p, att, sol, tol):
    assert sol.success, (sol.status, sol.max_constraint_violation)
    assert sol.terms[att.name] <= 1e-8
    rep = verify(eba, sol)
    print(f"restoration N={p.N}: final attitude error {rep.final_base_attitude_error_rad:.2e} rad, "
          f"NLP/simulator mismatch {rep.base_attitude_mismatch_rad:.2e} rad, {sol.iterations} it")
    assert rep.final_base_attitude_error_rad <= tol
    assert rep.base_attitude_mismatch_rad <= tol
    assert rep.max_momentum_residual < 1e-9
    # the straight-line path alone (no restoration) turns the base: the constraint did something
    from optplan.model.floating import simulate_base

    s = np.linspace(0, 1, 201)[:, None]
    sim = simulate_base(eba, (s[:, 0] * 20.0, Q0 + (10 * s**3 - 15 * s**4 + 6 * s**5) * (QF - Q0)),
                        s[:, 0] * 20.0)
    R = sim.final_base.rotation
    assert np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)) > 10 * tol
    return rep


@pytest.mark.slow
def test_attitude_restoration_eba(eba):
    """The EBA paper's θ0 → θf, N = 30 (≈ minutes: the exact-Hessian build of the floating base is slow;
    limited-memory Hessian avoids the multi-GB expansion)."""
    p, att, sol = _restoration(eba, 30, ipopt_options={"expand": False})
    _check_restoration(eba, p, att, sol, 1e-5)


def test_attitude_restoration_small(eba):
    """Same problem at N = 4 with a limited-memory Hessian (fast); RK4 with 2 sub-steps over 5 s
    intervals matches the independent simulator (10× denser) to ~1e-4 rad."""
    p, att, sol = _restoration(eba, 4, exact_hessian=False)
    _check_restoration(eba, p, att, sol, 2e-4)


# --------------------------------------------------------------------------- (g) conditioning
def _pinned_closed_chain_problem(tcb, N=12, shift_end=0.0, skip=True):
    """Both ends pinned on one closed-chain manifold (the end optionally moved off it)."""
    from optplan.constraints.closed_chain import project_closed_chain

    rng = np.random.default_rng(5)
    qa = tcb.random_joints(rng) * 0.4
    cc = dataclasses.replace(ClosedChain.from_configuration(tcb, qa), skip_pinned=skip)
    qb = project_closed_chain(tcb, qa + rng.normal(size=14) * 0.2, cc).q
    qb = qb + shift_end
    p = OptProblem(tcb, n_intervals=N, duration=5.0)
    p.add_constraint(JointBoundary("start", q=qa, qd=Z, qdd=Z))
    p.add_constraint(JointBoundary("end", q=qb, qd=Z, qdd=Z))
    h = p.add_constraint(cc)
    p.add_cost(Smoothness("jerk"))
    p.set_initial_straight_line(qa, qb)
    return p, h


def test_closed_chain_leaves_out_pinned_knots_it_holds_at(tcb):
    """At pinned knots that satisfy the closed chain the rows would repeat the boundary
    constraint (a rank-deficient Jacobian): they are left out, the residual still holds there."""
    p, h = _pinned_closed_chain_problem(tcb)
    p._build()
    assert p._con_slices[h.name].stop - p._con_slices[h.name].start == 7 * (p.N - 1)
    p_all, h_all = _pinned_closed_chain_problem(tcb, skip=False)   # the default keeps every knot
    p_all._build()
    assert p_all._con_slices[h_all.name].stop - p_all._con_slices[h_all.name].start == 7 * (p.N + 1)
    sol = p.solve()
    assert sol.success, sol.status
    full = verify(tcb, sol, closed_chain=h.term)   # every sample, ends included
    assert full.max_closed_chain_residual < 1e-4


def test_closed_chain_keeps_pinned_knots_it_is_violated_at(tcb):
    """A pinned end off the manifold keeps its rows: the problem is infeasible, and says so."""
    p, h = _pinned_closed_chain_problem(tcb, shift_end=0.05)
    p._build()
    assert p._con_slices[h.name].stop - p._con_slices[h.name].start == 7 * p.N
    sol = p.solve(max_iter=100)
    assert not sol.success and sol.terms[h.name] > 1e-3


def test_scaled_variables_round_trip_and_integration_rows_are_unit(tcb, ends):
    """The decision vector holds q, h₀q̇, h₀²q̈, h₀³j: pack/unpack round-trip in physical units, and
    the integration rows have O(1) coefficients (no h³ factors) whatever the interval."""
    import casadi as ca

    qa, qb = ends
    for T, N in ((0.5, 10), (200.0, 10)):
        p = rest_to_rest(tcb, qa, qb, N, "jerk", T)
        rng = np.random.default_rng(1)
        arrs = [rng.normal(size=(N + 1, 14)) for _ in range(3)] + [rng.normal(size=(N, 14))]
        x = p.tp.pack(*arrs)
        u = p.tp.unpack(x)
        for name, a in zip(("q", "qd", "qdd", "jerk"), arrs):
            np.testing.assert_allclose(u[name], a, rtol=1e-12, atol=1e-12)
        G, _, _ = p.tp.dynamics_constraints()
        J = np.array(ca.Function("j", [p.tp.x], [ca.jacobian(G, p.tp.x)])(x))
        nz = np.abs(J[J != 0])
        assert nz.min() >= 1 / 6 - 1e-12 and nz.max() <= 1 + 1e-12


def test_solution_reuse_requires_the_same_scaling(tcb, ends):
    """A solution's raw vector is reused only by a problem with the same knots *and* interval;
    otherwise it is resampled in physical units (the knot transcription's scaled variables)."""
    qa, qb = ends
    p = rest_to_rest(tcb, qa, qb, 8, "jerk", 3.0)
    p.transcription = "knots"
    p.set_initial_straight_line(qa, qb)
    sol = p.solve()
    assert sol.success and sol.x_scale_h == pytest.approx(3.0 / 8)
    p2 = rest_to_rest(tcb, qa, qb, 8, "jerk", 6.0)
    p2.transcription = "knots"
    p2.set_initial(solution=sol)
    u = p2.tp.unpack(p2.initial_guess)
    np.testing.assert_allclose(u["q"], sol.q, atol=1e-9)            # same shape in time
    np.testing.assert_allclose(u["qd"], sol.qd / 2, atol=1e-6)       # twice as slow


# --------------------------------------------------------------------------- boundary as bounds
def _moving_ends(tcb, qa, qb, fix, free_time=False):
    """Rest-free ends (given q̇ and q̈) between which a jerk optimum moves; fixed ends by bounds or rows."""
    rng = np.random.default_rng(5)
    v0, a0 = rng.uniform(-0.2, 0.2, 14), rng.uniform(-0.3, 0.3, 14)
    kw = {"free_time": True, "duration_bounds": (1.0, 6.0)} if free_time else {}
    p = OptProblem(tcb, n_intervals=12, duration=3.0, **kw)
    p.fix_boundary_points = fix
    p.add_constraint(JointBoundary("start", q=qa, qd=v0, qdd=a0))
    h = p.add_constraint(JointBoundary("end", q=qb, qd=Z, qdd=Z))
    p.add_cost(Smoothness("jerk"))
    if free_time:
        p.add_cost(Duration(), weight=1.0)
    return p, h, v0, a0


def test_boundary_fixed_by_bounds_is_the_rows_optimum_and_exact(tcb, ends):
    """A boundary that gives q, q̇ and q̈ fixes its end's three control points by bounds: the
    optimum is the one the equality rows give (an independent formulation), the boundary holds to
    rounding, the NLP has 3·nj rows fewer per end, and the handle still reports values,
    violations and the dual (checked against the rows' multipliers)."""
    qa, qb = ends
    p_b, h_b, v0, a0 = _moving_ends(tcb, qa, qb, fix=True)
    p_r, h_r, _, _ = _moving_ends(tcb, qa, qb, fix=False)
    for p in (p_b, p_r):
        p.set_initial_straight_line(qa, qb)
    s_b, s_r = p_b.solve(tol=1e-10), p_r.solve(tol=1e-10)
    assert s_b.success and s_r.success
    assert len(p_b._spline.fixed) == 2 and not p_r._spline.fixed
    np.testing.assert_allclose(s_b.q, s_r.q, atol=1e-7)
    assert s_b.cost == pytest.approx(s_r.cost, rel=1e-8)
    np.testing.assert_allclose(s_b.q[0], qa, atol=1e-12)
    np.testing.assert_allclose(s_b.qd[0], v0, atol=1e-12)
    np.testing.assert_allclose(s_b.qdd[0], a0, atol=1e-11)
    np.testing.assert_allclose(s_b.qd[-1], 0.0, atol=1e-12)
    assert s_b.lam_g is not None and s_r.lam_g is not None and s_r.lam_g.size - s_b.lam_g.size == 2 * 3 * 14
    np.testing.assert_allclose(s_b.value(h_b), s_r.value(h_r), atol=1e-7)
    assert s_b.violation(h_b).max() <= 1e-12 and s_b.terms[h_b.name] <= 1e-12
    np.testing.assert_allclose(s_b.dual(h_b), s_r.dual(h_r), rtol=1e-5, atol=1e-6 * np.abs(s_r.dual(h_r)).max())


def test_boundary_with_free_time_is_fixed_only_at_rest(tcb, ends):
    """With a free duration a moving end's points depend on T: only the rest end is fixed."""
    qa, qb = ends
    p, h_end, v0, _ = _moving_ends(tcb, qa, qb, fix=True, free_time=True)
    p.set_initial_straight_line(qa, qb)
    sol = p.solve()
    assert sol.success
    assert list(p._spline.fixed) == p._spline.owner[h_end.name]
    np.testing.assert_allclose(sol.qd[0], v0, atol=1e-6)
    np.testing.assert_allclose(sol.q[-1], qb, atol=1e-12)


def test_rows_at_a_fixed_end_that_hold_leave_the_nlp_and_are_still_reported(tcb):
    """The closed chain at two pinned rest ends that satisfy it: its rows there have no variable
    left (the ends are fixed by bounds) and leave the NLP; the optimum is the one with every row
    (an independent formulation), and ``violation``/``value`` still cover every knot."""
    from optplan.constraints.closed_chain import project_closed_chain

    rng = np.random.default_rng(5)
    qa = tcb.random_joints(rng) * 0.4
    cc = ClosedChain.from_configuration(tcb, qa)
    qb = project_closed_chain(tcb, qa + 0.1, cc).q
    Q = np.array([project_closed_chain(tcb, qa + s * (qb - qa), cc).q for s in np.linspace(0, 1, 7)])

    def make(fix):
        p = OptProblem(tcb, n_intervals=6, duration=3.0)
        p.fix_boundary_points = fix
        p.add_constraint(JointBoundary("start", q=qa, qd=Z, qdd=Z))
        p.add_constraint(JointBoundary("end", q=qb, qd=Z, qdd=Z))
        # the reference: boundary rows, the chain's rows left out at the pinned knots by the term
        # itself (with them the rows version's Jacobian is rank-deficient and IPOPT stalls)
        h = p.add_constraint(cc if fix else dataclasses.replace(cc, skip_pinned=True))
        p.add_cost(Smoothness("jerk"))
        p.set_initial(q=Q)
        return p, h

    (p_b, h_b), (p_r, h_r) = make(True), make(False)
    s_b, s_r = p_b.solve(tol=1e-9), p_r.solve(tol=1e-9)
    assert s_b.success, s_b.status
    assert s_r.success, s_r.status
    assert p_b._spline.constant == {p_b._spline.owner[h_b.name][0]: {0, 6}}
    assert s_r.lam_g.size - s_b.lam_g.size == 2 * 3 * 14
    np.testing.assert_allclose(s_b.q, s_r.q, atol=1e-7)
    assert s_b.violation(h_b).shape == (7, 7) and s_b.violation(h_b).max() <= 1e-8
    np.testing.assert_allclose(s_b.value(h_b)[1:-1], s_r.value(h_r), atol=1e-7)
    assert np.isnan(s_b.dual(h_b)[[0, -1]]).all() and np.isfinite(s_b.dual(h_b)[1:-1]).all()
