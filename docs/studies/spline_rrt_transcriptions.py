"""The Spline-RRT* optimized variant on both transcriptions, paired on the same plan (decision 0022).

    python docs/studies/spline_rrt_transcriptions.py [--seeds 0 1] [--order knots,bspline]

Per seed: plan, smooth and track once (Spline-RRT*), then solve the optimized variant with each
transcription from the same warm start and print the process CPU of build + solve, IPOPT's
iterations and the figures of the example (at the knots, on a dense grid, executed).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from optplan.model.robot import RobotModel
from optplan.papers.spline_rrt import (
    OptimizeOptions,
    SplineRRTTask,
    _time_scaled,
    evaluate,
    optimize,
    run_spline_rrt,
    track,
)
from optplan.planners.spline_rrt import CoordinatedRRTStarOptions


def figures(robot, task, hands, T, sol) -> dict:
    """The example's figures: at the knots, on a 0.05 s grid, and executed (resolved rates with
    the NLP's joints as the redundancy reference), from the independent base simulator."""
    t = np.linspace(0.0, T, int(round(T / 0.05)) + 1)
    s = sol.sample(t)
    dense = evaluate(robot, hands, t, s["q"], s["qd"], scene=task.scene, joint_accelerations=s["qdd"])
    kn = evaluate(robot, hands, sol.t, sol.q, sol.qd, scene=task.scene, joint_accelerations=sol.qdd)

    def reference(tt):
        smp = sol.sample([min(max(tt, 0.0), sol.t[-1])])
        return smp["q"][0], smp["qd"][0]
    x = track(robot, hands, task.q_start, T, None, reference=reference)
    ex = evaluate(robot, hands, x.t, x.joints, x.qd, scene=task.scene, joint_accelerations=x.qdd)
    arms = list(hands)
    out = {}
    for name, ev in (("knots", kn), ("dense", dense), ("exec", ex)):
        out[name] = {"pos_err_m": max(ev[f"tracking_position_m_{a}"].max() for a in arms),
                     "goal_ori_err_rad": max(ev[f"tracking_orientation_rad_{a}"][-1] for a in arms),
                     "base_err_rad": float(np.linalg.norm(ev["base_rpy"][-1])),
                     "min_link_m": float(ev["link_distance_m"].min()),
                     "min_obst_m": float(ev["obstacle_distance_m"].min()),
                     "max_rate_deg_s": float(np.degrees(ev["max_joint_rate_rad_s"])),
                     "max_acc_deg_s2": float(np.degrees(ev["max_joint_accel_rad_s2"]))}
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--order", default="knots,bspline")
    args = ap.parse_args()
    robot = RobotModel.from_name("splinerrt_ffsr")
    task = SplineRRTTask.from_scene(robot)
    for seed in args.seeds:
        po = CoordinatedRRTStarOptions(hand_radius=0.15, max_iterations=400, seed=seed, time_limit=5.0)
        res = run_spline_rrt(robot, task, plan_options=po, run_optimizer=False)
        if not res.success:
            print(f"seed {seed}: planning failed")
            continue
        for tr in args.order.split(","):
            oo = OptimizeOptions(transcription=tr)
            T_opt = res.T * oo.duration_factor
            hands = _time_scaled(res.hands, res.T, T_opt)
            c0, w0 = time.process_time(), time.perf_counter()
            sol, prob = optimize(robot, task, hands, T_opt, res.tracking, oo)
            cpu, wall = time.process_time() - c0, time.perf_counter() - w0
            f = figures(robot, task, hands, T_opt, sol)
            print(f"seed {seed} {tr:8s} {sol.status.value:>12s} success={sol.success} it={sol.total_iterations} "
                  f"cpu={cpu:.2f}s wall={wall:.2f}s setup={sol.setup_time:.2f}s ipopt_wall={sol.wall_time:.2f}s "
                  f"cost={sol.cost:.6g}", flush=True)
            for k, v in f.items():
                print(f"    {k:6s} " + " ".join(f"{n}={x:.3e}" for n, x in v.items()), flush=True)


if __name__ == "__main__":
    main()
