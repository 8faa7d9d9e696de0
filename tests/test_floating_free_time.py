"""A free-floating robot with a free final time and collision rows on the B-spline kernel core:
the free-floating reach with joint velocity/acceleration limits and free final time (the
``reach_free_time`` task of ``optplan bench modelling``) plus ``CollisionAvoidance`` with a sphere
its solution without collision rows passes through. Checked independently: ``verify`` (coal on
every pair, the base re-integrated by the simulator), Pinocchio for the hand and the base
attitude, the limits sampled densely; and the assembled exact derivatives of such a problem
(duration column included) against central finite differences of its constraint function."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from optplan.bench.modelling import _check_reach, _reach, reach_probe_scene
from optplan.problem import CollisionAvoidance, OptProblem
from optplan.problem.frame_terms import BaseAttitude
from optplan.problem.terms import Duration, JointBoundary, JointVelocityLimits, Smoothness
from optplan.verification import VerifyTolerances, verify


def test_free_time_reach_with_collision_solves_on_the_bspline_core_and_verifies(eba):
    plain, _ = _reach(True)
    s0 = plain.solve()
    assert s0.success and plain.uses_bspline()
    scene = reach_probe_scene()
    rep0 = verify(eba, s0, scene, held_object=False)
    assert rep0.min_clearance_m < -0.01 and "probe" in rep0.min_clearance_pair   # without rows it collides

    prob, ctx = _reach(True, collision=True)
    assert prob.uses_bspline()                        # no fallback to the knot transcription
    sol = prob.solve()
    assert sol.success, (sol.status, [a.label for a in sol.attempts])
    assert prob.uses_bspline() and type(sol.evaluator).__name__ == "SplineEvaluator"
    # the duration is a decision variable: not the nominal 20 s, within its bounds
    lo, hi = prob.duration_bounds
    assert lo <= sol.duration <= hi and abs(sol.duration - 20.0) > 0.1
    # independent checks: coal along the re-integrated base (all pairs), hand and attitude by Pinocchio
    rep = verify(eba, sol, scene, held_object=False)
    tol = VerifyTolerances(final_base_attitude_rad=None)
    assert rep.passed(tol), rep.failures(tol)
    assert rep.min_clearance_m >= 0.01 - 1e-3 and rep.max_momentum_residual < 1e-8
    got = _check_reach(prob, sol, ctx)
    assert got["hand_error_m"] < 1e-6 and got["base_attitude_error_rad"] < 1e-6
    assert got["arm_b_motion_rad"] < 1e-6
    assert got["max_velocity_rad_s"] <= 0.1 + 1e-6 and got["max_acceleration_rad_s2"] <= 0.02 + 1e-6
    assert got["min_clearance_m"] == pytest.approx(rep.min_clearance_m)


def test_free_time_collision_derivatives_match_finite_differences(eba):
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
