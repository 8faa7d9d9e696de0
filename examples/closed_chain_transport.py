#!/usr/bin/env python3
"""Closed-chain transport: the two arms of `tcbirrt_dual_arm` hold the 2 x 0.8 x 0.8 m
object and carry it between two poses around obstacles (scene `models/scenes/transport.toml`).

Initial guess: the straight line between the two object poses (position linear, orientation in
exponential coordinates) mapped through closed-chain IK; it passes through an obstacle. IPOPT then
solves the NLP (closed chain, joint limits, collision avoidance, minimum jerk), and `verify` checks
the result at 10x the knot density with Pinocchio and coal, independently of the NLP.

    python examples/closed_chain_transport.py [--knots 50] [--json out.json] [--save traj.npz] [--html view.html]

Exit code 0 only when IPOPT converged and verification passed (closed-chain residual <= 1e-6,
clearance >= 0).
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from optplan import RobotModel
from optplan.collision.checker import CollisionChecker
from optplan.scene import Scene
from optplan.tasks import transport_initial_path, transport_problem
from optplan.verification import verify


def run(knots: int = 50, duration: float = 60.0, seed: int = 0, margin: float = 0.02, scene_name: str = "transport",
        transcription: str = "bspline"):
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    scene = Scene.load(scene_name)
    rng = np.random.default_rng(seed)
    checker = CollisionChecker(robot, scene)
    t0 = time.perf_counter()
    Q = transport_initial_path(robot, scene, knots, rng, checker=checker)
    if Q is None:
        return {"success": False, "ipopt_status": "no_initial_guess",
                "message": "no collision-free start grasp whose straight-line IK path reaches the goal"}, None
    ik_time = time.perf_counter() - t0
    clearance0 = min(checker.min_distance(q)[0] for q in Q)
    if transcription == "bspline":  # the B-spline segment NLP (optplan.problem.segment)
        from optplan.problem import ClosedChain
        from optplan.problem.segment import SegmentSpec, SplineSegmentProblem

        arms = list(scene.object.grasps)
        cc = ClosedChain.from_grasps(scene.object.grasps[arms[0]], scene.object.grasps[arms[1]], arms[0], arms[1])
        t1, c1 = time.perf_counter(), time.process_time()
        prob = SplineSegmentProblem(robot, scene, SegmentSpec(knots, duration, Q[0], Q[-1], cc, margin=margin,
                                                              object_arm=arms[0]))
        prob.set_initial(Q)
        col = prob.col
    elif transcription == "knots":
        t1, c1 = time.perf_counter(), time.process_time()
        prob, cc, col = transport_problem(robot, scene, Q, duration=duration, margin=margin)
    else:
        raise ValueError(f"transcription: expected 'bspline' or 'knots', got {transcription!r}")
    sol = prob.solve()
    total_opt = time.perf_counter() - t1
    total_cpu = time.process_time() - c1
    rep = verify(robot, sol, scene, closed_chain=cc)
    ok = bool(sol.success and rep.max_closed_chain_residual <= 1e-6 and rep.min_clearance_m >= 0.0)
    out = {
        "success": ok,
        "ipopt_status": sol.status.value,
        "iterations": sol.iterations,
        "solve_time_s": sol.wall_time,
        "setup_time_s": sol.setup_time,
        "build_and_solve_time_s": total_opt,
        "build_and_solve_cpu_s": total_cpu,
        "transcription": transcription,
        "ik_time_s": ik_time,
        "n_knots": knots + 1,
        "max_closed_chain_residual": rep.max_closed_chain_residual,
        "min_clearance_m": rep.min_clearance_m,
        "min_clearance_pair": rep.min_clearance_pair,
        "initial_guess_min_clearance_m": clearance0,
        "max_position_limit_violation": rep.max_position_limit_violation,
        "max_velocity_limit_violation": rep.max_velocity_limit_violation,
        "active_collision_pairs": _active_pairs(prob, col, transcription),
        "cost": sol.cost,
    }
    return out, sol


def _active_pairs(prob, col, transcription: str) -> int:
    """Number of collision pairs with rows in the NLP."""
    if col is None:
        return 0
    if transcription == "bspline":
        return len(col.active_pairs)  # the segment NLP's CollisionModel
    return len(prob.term_data("collision").info.get("active_pairs", ()))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--knots", type=int, default=50, help="number of intervals N (N+1 knots)")
    ap.add_argument("--duration", type=float, default=60.0, help="motion duration [s]")
    ap.add_argument("--margin", type=float, default=0.02, help="required clearance in the NLP [m]")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--transcription", choices=["bspline", "knots"], default="bspline",
                    help="trajectory NLP: B-spline control points (default) or the knot-state transcription")
    ap.add_argument("--json", help="write the figures as JSON")
    ap.add_argument("--save", help="write the trajectory (npz: t, q, joint_names)")
    ap.add_argument("--plot", help="directory for PNG figures")
    ap.add_argument("--html", help="write a 3D view of the motion (self-contained HTML; extra 'viz')")
    args = ap.parse_args(argv)
    out, sol = run(args.knots, args.duration, args.seed, args.margin, transcription=args.transcription)
    print("closed-chain transport (tcbirrt_dual_arm, scene 'transport')")
    for k in ("success", "ipopt_status", "iterations", "solve_time_s", "setup_time_s", "n_knots", "max_closed_chain_residual",
              "min_clearance_m", "initial_guess_min_clearance_m"):
        if k in out:
            v = out[k]
            print(f"  {k:32s} {v:.3e}" if isinstance(v, float) else f"  {k:32s} {v}")
    print("  targets: N=50 built and solved in <= 0.3 s, closed-chain residual <= 1e-6, clearance >= 0 (coal)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    if args.save and sol is not None:
        t = np.linspace(sol.t[0], sol.t[-1], 10 * (len(sol.t) - 1) + 1)
        np.savez(args.save, t=t, q=sol.sample(t)["q"], joint_names=np.array(sol.joint_names))
    if args.plot and sol is not None:
        from optplan.viz import plot_joint_trajectory

        plot_joint_trajectory(sol, args.plot, "closed_chain_transport")
    if args.html and sol is not None:
        from optplan.viz.outputs import write_views

        t = np.linspace(sol.t[0], sol.t[-1], 10 * (len(sol.t) - 1) + 1)
        for p in write_views(RobotModel.from_name("tcbirrt_dual_arm"), Scene.load("transport"), t, sol.sample(t)["q"],
                             html=args.html, title="closed-chain transport"):
            print(f"  wrote {p}")
    return 0 if out["success"] else 1


if __name__ == "__main__":
    sys.exit(main())
