"""The derivative registry (tests/test_problem_terms.py), B-spline core part: a free duration with a
floating robot's collision rows (world planes with the base attitude, plane offsets after T). The
core's terms are compared with CasADi's own derivatives in tests/test_model_expr.py; this problem's
assembled Jacobian and Hessian are checked against central finite differences of the NLP's own
constraint and objective functions."""
from __future__ import annotations

import casadi as ca
import numpy as np

from optplan.bench.modelling import reach_probe_scene
from optplan.problem import (
    BaseAttitude,
    CollisionAvoidance,
    Duration,
    JointBoundary,
    JointVelocityLimits,
    OptProblem,
    Smoothness,
)


def test_spline_free_time_floating_collision_derivatives_match_finite_differences(eba):
    """Exact Jacobian and Hessian of the assembled NLP (world plane rows with the base attitude,
    velocity rows N ΔP − v·T, RK4 attitude and momentum rows, the duration's cost) against
    central differences of the NLP's own constraint and objective functions."""
    scene = reach_probe_scene()
    q0 = np.r_[[0.3, -0.6, 0.4, -1.2, 0.2, 0.7, 0.1] * 2]
    q1 = q0 + np.r_[[0.5, 0.3, -0.2, 0.4, 0.1, -0.3, 0.2], [0.0] * 7]
    z = np.zeros(eba.nj)
    prob = OptProblem(eba, n_intervals=6, duration=8.0, free_time=True, duration_bounds=(1.0, 50.0),
                      transcription="bspline", compile_kernels=False)
    prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=q1, qd=z, qdd=z))
    prob.add_constraint(JointVelocityLimits(limit=0.2))
    prob.add_constraint(BaseAttitude(at="end"))
    prob.add_constraint(CollisionAvoidance(scene, margin=0.01, held_object=False, fixed_normals=True,
                                           activation=5.0))   # every pair, so that the rows exist here
    prob.add_cost(Duration())
    prob.add_cost(Smoothness("jerk"), weight=1e-2)
    assert prob.uses_bspline()
    be = prob._spline
    core = be.core
    assert core.i_T is not None and core.nx > core.x_aux          # T and the planes' offsets both present
    fam = [f for f in be.fams if f.kind == "pair"]
    assert any(f.data["world"] for f in fam), "no world plane rows"
    st = core.structure(be.row_families(), bool(be.pbounds), False)
    rng = np.random.default_rng(11)
    x = be.guess(8.0)
    x = x + rng.normal(size=x.size) * 0.01
    x[core.i_T] = 9.3
    p = be._pvec(8.0, be._com0(q0), 0.7)
    G, J = st["derivs"]["jac_g"](x, p)
    J = np.array(ca.densify(J))
    gfun = st["gfun"]
    eps = 1e-6
    cols = list(rng.choice(core.nx, size=40, replace=False)) + [core.i_T, core.nx - 1]
    cols += [int(core.slot_xi(core.N)[0])]
    for j in cols:
        e = np.zeros(core.nx)
        e[j] = eps
        fd = (np.array(gfun(x + e, p)).ravel() - np.array(gfun(x - e, p)).ravel()) / (2 * eps)
        assert np.abs(J[:, j] - fd).max() <= 1e-5 * max(1.0, np.abs(fd).max()), j
    # the duration enters the velocity rows and the jerk and duration costs, not the plane rows
    assert np.abs(J[:, core.i_T]).max() > 0
    for f in fam:
        assert not np.any(J[st["slices"][f.name], core.i_T])
    # Hessian of the Lagrangian: central differences of its gradient ∇f·σ + Jᵀλ
    lam = rng.normal(size=G.shape[0])
    sigma = 1.3
    H = np.array(ca.densify(st["derivs"]["hess_lag"](x, p, sigma, lam)))
    H = np.triu(H) + np.triu(H, 1).T

    def grad_l(xx):
        _, gf = st["derivs"]["grad_f"](xx, p)
        _, Jx = st["derivs"]["jac_g"](xx, p)
        return sigma * np.array(gf).ravel() + np.array(ca.densify(Jx)).T @ lam

    for j in cols[:15] + cols[-3:]:
        e = np.zeros(core.nx)
        e[j] = eps
        fd = (grad_l(x + e) - grad_l(x - e)) / (2 * eps)
        assert np.abs(H[:, j] - fd).max() <= 1e-4 * max(1.0, np.abs(fd).max()), j
    assert np.abs(H[:, core.i_T]).max() > 0
    # the base attitude of the end knot is a variable the world rows depend on
    xi_end = core.slot_xi(core.N)
    world = [f for f in fam if f.data["world"] and core.N in f.points]
    if world:
        assert np.any(J[st["slices"][world[0].name]][:, xi_end])
