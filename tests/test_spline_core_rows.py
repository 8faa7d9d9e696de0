"""Costs and rows of the B-spline core with a fixed duration.

* ``Smoothness`` jerk / acceleration enter the NLP as one constant quadratic form of the control
  points (no kernel family): checked against numpy integrals of the spline's own jerk and
  acceleration (:func:`bspline.knot_values`), the assembled gradient and Hessian against central
  finite differences of that integral.
* ``JointVelocityLimits`` is one two-sided row per velocity control point entry: its violations are
  reported in rad/s against the velocity control points computed from the solution's own
  control points."""
from __future__ import annotations

import numpy as np
import pytest

from optplan.problem import JointBoundary, JointVelocityLimits, OptProblem, Smoothness
from optplan.problem.bspline import knot_values


def _problem(tcb, rng, rows: bool, T: float = 2.7, N: int = 7):
    prob = OptProblem(tcb, n_intervals=N, duration=T, transcription="bspline")
    prob.compile_kernels = False
    wj, wa = 0.8, 2.5
    prob.add_cost(Smoothness("jerk"), weight=wj)
    prob.add_cost(Smoothness("acceleration"), weight=wa)
    if rows:
        q0 = tcb.random_joints(rng) * 0.3
        prob.add_constraint(JointBoundary("start", q=q0))
    assert prob.uses_bspline()
    be = prob._spline
    core = be.core
    st = core.structure(be.row_families(), bool(be.pbounds), False)
    return prob, be, core, st, (wj, wa)


def _integrals(core, x, T, w):
    """Exact ∫‖j‖² dt and ∫‖q̈‖² dt of the spline of x (jerk constant, q̈ linear per interval)."""
    h = T / core.N
    kv = knot_values(core.control_points(x), h)
    jerk = h * np.sum(kv["jerk"] ** 2)
    a = kv["qdd"]
    acc = h / 3 * np.sum(a[:-1] ** 2 + a[:-1] * a[1:] + a[1:] ** 2)
    return w[0] * jerk, w[1] * acc


@pytest.mark.parametrize("rows", [True, False])
def test_quadratic_costs_equal_the_splines_integrals_and_their_derivatives(tcb, rows):
    rng = np.random.default_rng(3)
    prob, be, core, st, w = _problem(tcb, rng, rows)
    fams = {f.name: f for f in be.fams if f.cost}
    assert fams and all(core.is_quadratic(f) for f in fams.values())
    T, scale = 2.7, 0.37
    p = be._pvec(T, np.zeros(3), scale)
    x = rng.normal(size=core.nx) * 0.4
    # per-family values (what the solution reports) and the objective
    c = np.array(st["cfun"](x, p)).ravel()
    jerk, acc = _integrals(core, x, T, w)
    names = list(fams)
    vals = {fams[n].kind: c[st["cslices"][n]].sum() for n in names}
    assert vals["jerk"] == pytest.approx(jerk, rel=1e-10)
    assert vals["acceleration"] == pytest.approx(acc, rel=1e-10)
    f, g = st["derivs"]["grad_f"](x, p)
    assert float(f) == pytest.approx(scale * (jerk + acc), rel=1e-10)

    def fnum(xv):
        return scale * sum(_integrals(core, xv, T, w))

    # gradient and Hessian (σ ∇²f; λ = 0 for the rows) against central finite differences (exact
    # for a quadratic up to rounding: steps of 0.1)
    g = np.array(g).ravel()
    sigma = 1.7
    H = np.array(st["derivs"]["hess_lag"](x, p, sigma, np.zeros(st["lbg"].size)))
    H = np.triu(H) + np.triu(H, 1).T
    for i in rng.choice(core.nx, 6, replace=False):
        e = np.zeros(core.nx)
        e[i] = 0.1
        assert g[i] == pytest.approx((fnum(x + e) - fnum(x - e)) / 0.2, rel=1e-8, abs=1e-8)
        for j in rng.choice(core.nx, 3, replace=False):
            d = np.zeros(core.nx)
            d[j] = 0.1
            fd = (fnum(x + e + d) - fnum(x + e - d) - fnum(x - e + d) + fnum(x - e - d)) / (4 * 0.01)
            assert H[i, j] == pytest.approx(sigma * fd, rel=1e-8, abs=1e-8)


def test_a_free_duration_keeps_the_kernel_family(tcb):
    """With T a decision variable the cost is not a quadratic form of x: it stays a kernel family."""
    prob = OptProblem(tcb, n_intervals=6, free_time=True, duration=2.0, transcription="bspline")
    prob.add_cost(Smoothness("jerk"), weight=1.0)
    assert prob.uses_bspline()
    be = prob._spline
    assert not any(be.core.is_quadratic(f) for f in be.fams)


def test_two_sided_velocity_rows_report_violations_in_rad_per_s(tcb):
    """Ends 0.6 rad apart in 1 s under a 0.3 rad/s limit on one joint: infeasible; the worst rows
    are that joint's velocity entries, valued as the velocity control points of the solution."""
    N, T = 6, 1.0
    q0 = np.zeros(tcb.nj)
    q1 = q0.copy()
    q1[1] = 0.6
    hi = np.full(tcb.nj, 10.0)
    hi[1] = 0.3
    prob = OptProblem(tcb, n_intervals=N, duration=T, transcription="bspline")
    prob.compile_kernels = False
    prob.add_constraint(JointBoundary("start", q=q0, qd=0 * q0, qdd=0 * q0))
    prob.add_constraint(JointBoundary("end", q=q1, qd=0 * q0, qdd=0 * q0))
    prob.add_constraint(JointVelocityLimits(limit=hi, activation=0.0))
    prob.add_cost(Smoothness("jerk"))
    sol = prob.solve(max_iter=60, guarantees=False)
    assert not sol.success
    fam = next(f for f in prob._spline.fams if f.kind == "velocity")
    assert fam.rows_per_point == 1
    V = np.diff(prob._spline.core.control_points(np.asarray(sol.x)), axis=0) * N / T   # (N+2) × nj
    bad = [r for r in prob.infeasibilities(sol, 50) if r.term == "velocity_limits"]
    assert bad
    jn = tcb.joint_names[1]
    for r in bad:
        assert r.label.startswith(f"velocity_limits[{jn}].upper at t="), r.label
        i = int(r.point)
        assert r.value == pytest.approx(V[i, 1], abs=1e-9)
        assert r.violation == pytest.approx(V[i, 1] - 0.3, abs=1e-9)


@pytest.mark.parametrize("kind", ["velocity", "acceleration"])
def test_own_lower_and_upper_override_the_symmetric_limit(tcb, kind):
    """``lower``/``upper`` of a velocity or acceleration limit are the bounds the solve keeps
    (they used to be ignored): an asymmetric box, a rest-to-rest move whose straight-line
    velocity breaks it, and the solution's densely sampled q̇ / q̈ inside it."""
    from optplan.problem import JointAccelerationLimits

    nj = tcb.nj
    vel = kind == "velocity"
    T = 2.0 if vel else 3.0   # straight quintic: peak q̇ 0.56 rad/s > 0.5, peak q̈ 0.19 rad/s² > 0.15
    q0, q1 = np.zeros(nj), np.full(nj, 0.6 if vel else 0.3)
    lo, hi = np.full(nj, -0.05 if vel else -0.5), np.full(nj, 0.5 if vel else 0.15)
    term = (JointVelocityLimits(limit=5.0, lower=lo, upper=hi) if vel
            else JointAccelerationLimits(limit=5.0, lower=lo, upper=hi))
    got_lo, got_hi = term.limits(tcb)
    assert np.allclose(got_hi, hi) and np.all(got_lo < 0) and np.all(got_lo > -5.0)
    prob = OptProblem(tcb, n_intervals=10, duration=T, transcription="bspline")
    prob.compile_kernels = False
    prob.add_constraint(JointBoundary("start", q=q0, qd=np.zeros(nj), qdd=np.zeros(nj)))
    prob.add_constraint(JointBoundary("end", q=q1, qd=np.zeros(nj), qdd=np.zeros(nj)))
    prob.add_constraint(term)
    prob.add_cost(Smoothness("jerk"))
    sol = prob.solve()
    assert sol.success, sol.status
    key = "qd" if kind == "velocity" else "qdd"
    v = sol.sample(np.linspace(0.0, T, 401))[key]
    assert v.max() <= hi.max() + 1e-6 and v.min() >= got_lo.min() - 1e-6
    assert v.max() > 0.9 * hi.max()   # the upper bound is active: 5.0 would have left it free
    with pytest.raises(Exception, match="lower > upper"):
        JointVelocityLimits(lower=hi, upper=lo)
