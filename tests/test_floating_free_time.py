"""A free-floating robot with a free final time and collision rows on the B-spline kernel core:
the free-floating reach with joint velocity/acceleration limits and free final time (the
``reach_free_time`` task of ``optplan bench modelling``) plus ``CollisionAvoidance`` with a sphere
its solution without collision rows passes through. Checked independently: ``verify`` (coal on
every pair, the base re-integrated by the simulator), Pinocchio for the hand and the base
attitude, the limits sampled densely. (The exact derivatives of such a problem, duration column
included, against finite differences: ``tests/test_problem_terms.py``, B-spline core section.)"""
from __future__ import annotations

import pytest

from optplan.bench.modelling import _check_reach, _reach, reach_probe_scene
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
