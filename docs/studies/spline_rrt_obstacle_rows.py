"""Why the Spline-RRT* optimized variant's B-spline NLP stalls with the obstacle rows: the same
problem solved with different IPOPT settings, paired on the same plan and warm start.

    python docs/studies/spline_rrt_obstacle_rows.py [--seeds 0 1 2] [--variants cd,nocd] [--max-iter 300]

Per seed: plan, smooth and track once (Spline-RRT*), build the B-spline problem of
``optimized._spline_problem`` and solve it from the tracked warm start for each variant (a fresh
problem each time, no dense check): ``cd``/``nocd`` IPOPT's ``perturb_always_cd`` yes/no (the rest
as the core's defaults for a problem with plane rows), ``cd8``: yes with IPOPT's default
``jacobian_regularization_value`` 1e-8 (the core's is 1e-6), ``mono``: also ``mu_strategy`` monotone and
IPOPT's own ``theta_max_fact``. Prints status, IPOPT iterations summed over the core's re-solves,
process CPU of build + solve and the cost.
"""
from __future__ import annotations

import argparse
import time

from optplan.model.robot import RobotModel
from optplan.papers.spline_rrt import OptimizeOptions, SplineRRTTask, _time_scaled, run_spline_rrt
from optplan.papers.spline_rrt.optimized import _spline_problem
from optplan.planners.spline_rrt import CoordinatedRRTStarOptions

VARIANTS: dict[str, dict[str, object]] = {
    "default": {},
    "cd": {"perturb_always_cd": "yes"},
    "nocd": {"perturb_always_cd": "no"},
    "cd8": {"perturb_always_cd": "yes", "jacobian_regularization_value": 1e-8},
    "mono": {"perturb_always_cd": "no", "mu_strategy": "monotone", "theta_max_fact": 1e4},
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--variants", default="cd,nocd")
    ap.add_argument("--max-iter", type=int, default=300)
    args = ap.parse_args()
    robot = RobotModel.from_name("splinerrt_ffsr")
    task = SplineRRTTask.from_scene(robot)
    for seed in args.seeds:
        po = CoordinatedRRTStarOptions(hand_radius=0.15, max_iterations=400, seed=seed, time_limit=5.0)
        res = run_spline_rrt(robot, task, plan_options=po, run_optimizer=False)
        if not res.success:
            print(f"seed {seed}: planning failed", flush=True)
            continue
        oo = OptimizeOptions(transcription="bspline")
        T = res.T * oo.duration_factor
        hands = _time_scaled(res.hands, res.T, T)
        for v in args.variants.split(","):
            c0 = time.process_time()
            prob = _spline_problem(robot, task, hands, T, oo)
            assert res.tracking is not None   # a successful plan is tracked
            prob.set_initial(q=res.tracking.joints, t=res.tracking.t)
            sol = prob.solve(dict(VARIANTS[v]), tol=oo.tol, max_iter=args.max_iter, guarantees=False)
            cpu = time.process_time() - c0
            print(f"seed {seed} {v:8s} {sol.status.value:>28s} it={sol.total_iterations:4d} "
                  f"({'+'.join(str(a.iterations) for a in sol.attempts)}) cpu={cpu:6.2f}s cost={sol.cost:.6g} "
                  f"viol={sol.max_constraint_violation:.1e}", flush=True)


if __name__ == "__main__":
    main()
