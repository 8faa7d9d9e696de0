"""Which term stalls the Spline-RRT* optimized variant on the B-spline core (decision 0022).

    python docs/studies/spline_rrt_bspline_terms.py --terms path,goal,attitude,limits,rates,orientation,links
    python docs/studies/spline_rrt_bspline_terms.py --terms path,goal,attitude,limits,rates,obstacles

Plans, smooths and tracks seed 0 as ``run_spline_rrt``, then solves the B-spline problem of
``optimized._spline_problem`` restricted to the given terms (boundary at rest and the jerk cost
always), from the tracked warm start, without the dense check; prints IPOPT's status, iterations
and the process CPU of the solve.
"""
from __future__ import annotations

import argparse
import time

import casadi as ca
import numpy as np

from optplan.model.robot import RobotModel
from optplan.papers.spline_rrt import SplineRRTTask, _time_scaled, knot_selector, run_spline_rrt
from optplan.planners.spline_rrt import CoordinatedRRTStarOptions
from optplan.problem import (
    BaseAttitude,
    CollisionAvoidance,
    JointAccelerationLimits,
    JointBoundary,
    JointPositionLimits,
    JointVelocityLimits,
    OptProblem,
    Smoothness,
)
from optplan.problem.terms import pose_residual


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--terms", default="path,goal,attitude,limits,rates,orientation,links,obstacles")
    ap.add_argument("--max-iter", type=int, default=150)
    args = ap.parse_args()
    terms = set(args.terms.split(","))
    robot = RobotModel.from_name("splinerrt_ffsr")
    task = SplineRRTTask.from_scene(robot)
    po = CoordinatedRRTStarOptions(hand_radius=0.15, max_iterations=400, seed=0, time_limit=5.0)
    res = run_spline_rrt(robot, task, plan_options=po, run_optimizer=False)
    T = 1.5 * res.T
    hands = _time_scaled(res.hands, res.T, T)
    N = 30
    prob = OptProblem(robot, N, T, n_sub=2, transcription="bspline")
    zero = np.zeros(robot.nj)
    prob.add_constraint(JointBoundary("start", q=task.q_start, qd=zero, qdd=zero))
    prob.add_constraint(JointBoundary("end", qd=zero))
    w = knot_selector(prob.t, prob.T, N)
    for a, h in hands.items():
        fr = prob.frame(robot.arm(a).ee_frame)
        poses = [h.pose(t) for t in np.linspace(0.0, T, N + 1)]
        if "path" in terms:
            P = prob.parameter((3, N + 1), np.array([M.translation for M in poses]).T)
            prob.add_constraint(fr.translation - P @ w, lower=0.0, upper=0.0, name=f"path_{a}")
        if "goal" in terms:
            r, tr = pose_residual(fr.rotation, fr.translation, poses[-1].rotation, fr.translation)
            prob.add_constraint(ca.vertcat(r[3:], tr), lower=np.r_[0.0, 0.0, 0.0, 1.0],
                                upper=np.r_[0.0, 0.0, 0.0, np.inf], at="end", name=f"goal_{a}")
        if "orientation" in terms:
            Rp = prob.parameter((9, N + 1), np.array([M.rotation.ravel(order="F") for M in poses]).T)
            r, _ = pose_residual(fr.rotation, fr.translation, ca.reshape(Rp @ w, 3, 3), fr.translation)
            prob.add_cost(r[3:], weight=N / T, name=f"orientation_{a}")
    if "attitude" in terms:
        prob.add_constraint(BaseAttitude(at="end"))
    if "limits" in terms:
        prob.add_constraint(JointPositionLimits())
    if "rates" in terms:
        prob.add_constraint(JointVelocityLimits(limit=0.995 * robot.velocity_limit))
        prob.add_constraint(JointAccelerationLimits(limit=0.1))
    if "links" in terms:
        prob.add_constraint(CollisionAvoidance(None, margin=0.1, self_collision=True, held_object=False,
                                               fixed_normals=True), name="links")
    if "obstacles" in terms:
        prob.add_constraint(CollisionAvoidance(task.scene, margin=0.0, self_collision=False, held_object=False,
                                               fixed_normals=True), name="obstacles")
    prob.add_cost(Smoothness("jerk"))
    prob.set_initial(q=res.tracking.joints, t=res.tracking.t)
    c0 = time.process_time()
    sol = prob.solve(tol=1e-8, max_iter=args.max_iter, guarantees=False)
    print(f"terms {sorted(terms)}: {sol.status.value}, {sol.iterations} iterations, solve CPU "
          f"{time.process_time() - c0:.2f} s, setup {sol.setup_time:.2f} s wall", flush=True)


if __name__ == "__main__":
    main()
