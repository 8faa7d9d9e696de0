"""Joint torques in an OptProblem, and what ``success`` guarantees between knots.

1. The CasADi recursive Newton-Euler against Pinocchio on every shipped robot (max |error| over
   random states; build and evaluation times).
2. A fast point-to-point move of ``tcbirrt_dual_arm`` with a tight torque limit on one joint:
   the knot-only solve (``solve_knots``) and ``solve`` (dense check + refinement), torques
   re-checked with ``pinocchio.rnea`` at 20× the knots.
3. With example-robot-data installed (extra ``robots``): a UR5 (collision meshes replaced by their
   bounding boxes) passing one box under a 0.02 m margin, knot-only vs ``solve``, clearance by
   ``verify`` (coal at 10× the knots).
4. ``--random M``: M random small problems (one arm of ``tcbirrt_dual_arm`` past a random box,
   random margin, N = 6): how often the knot-only solve reports success with the margin missed
   between knots, and how ``solve`` ends (exact coal distances at 10× the knots).

5. ``--transport``: the shipped closed-chain transport on the knot transcription (N = 50, margin
   0.02 m), knot-only vs ``solve``, and the time of the dense check.

    python examples/dynamics_and_guarantees.py [--skip-ur5] [--random 20] [--transport]
"""
from __future__ import annotations

import sys
import time

import numpy as np
import pinocchio as pin

from optplan.model.dynamics import SymbolicDynamics
from optplan.model.robot import RobotModel
from optplan.problem import (
    CollisionAvoidance,
    JointBoundary,
    JointTorqueLimits,
    OptProblem,
    Smoothness,
    check_between_knots,
)
from optplan.scene import Obstacle, Scene
from optplan.verification import verify


def rnea_accuracy(rng: np.random.Generator, n: int = 50) -> None:
    print("1. CasADi RNEA vs Pinocchio (random states)")
    for name in ("tcbirrt_dual_arm", "dshdasr", "eba_ffsr", "splinerrt_ffsr"):
        r = RobotModel.from_name(name)
        m, d = r.model, r.model.createData()
        t0 = time.perf_counter()
        sd = SymbolicDynamics(r)
        f = sd.rnea_function
        build = time.perf_counter() - t0
        err, te, tp = 0.0, 0.0, 0.0
        for _ in range(n):
            q = r.random_configuration(rng)
            v, a = rng.normal(size=m.nv) * 2, rng.normal(size=m.nv) * 5
            t1 = time.perf_counter()
            x = np.array(f(q, v, a)).ravel()
            t2 = time.perf_counter()
            ref = pin.rnea(m, d, q, v, a)
            t3 = time.perf_counter()
            te, tp = te + t2 - t1, tp + t3 - t2
            err = max(err, float(np.abs(x - ref).max() / max(1.0, np.abs(ref).max())))
        print(f"   {name:18s} nv={m.nv:2d}  max rel. error {err:.1e}  build {build * 1e3:.0f} ms  "
              f"eval {te / n * 1e6:.0f} µs (CasADi VM) vs {tp / n * 1e6:.0f} µs (pin.rnea)  "
              f"tau: {sd.tau.n_nodes()} SX nodes")


def torque_move() -> None:
    print("2. torque-limited move (tcbirrt_dual_arm, 1 s, a_joint2 limited to 2800 N·m)")
    r = RobotModel.from_name("tcbirrt_dual_arm")
    q0 = r.neutral()
    q1 = q0.copy()
    q1[1] += 0.8
    q1[3] += 0.6
    lim = np.full(r.nj, 1e5)
    lim[1] = 2800.0
    for how in ("solve_knots", "solve"):
        z = np.zeros(r.nj)
        prob = OptProblem(r, n_intervals=12, duration=1.0)
        prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
        prob.add_constraint(JointBoundary("end", q=q1, qd=z, qdd=z))
        prob.add_cost(Smoothness("jerk"))
        h = prob.add_constraint(JointTorqueLimits(limit=lim))
        prob.set_initial_straight_line(q0, q1)
        t0 = time.perf_counter()
        sol = getattr(prob, how)()
        dt = time.perf_counter() - t0
        ts = np.linspace(0.0, 1.0, 20 * (len(sol.t) - 1) + 1)
        s = sol.sample(ts)
        dense = max(abs(pin.rnea(r.model, r.data, q, v, a)[1]) for q, v, a in zip(s["q"], s["qd"], s["qdd"]))
        print(f"   {how:11s} success={sol.success}  N={prob.N}  iterations {sol.total_iterations} "
              f"({[a.label or 'first' for a in sol.attempts]})  {dt:.2f} s  |τ| at knots "
              f"{np.abs(sol.value(h)[:, 1]).max():.2f}, at 20× the knots {dense:.2f} N·m; "
              f"max |dual| {np.abs(sol.dual(h)).max():.3f}")


def _ur5() -> RobotModel | None:
    from optplan.model._robot_data import example_robot_data_dir
    from optplan.model.mesh_boxes import collision_meshes_as_boxes

    share = example_robot_data_dir()
    urdf = None if share is None else share / "robots/ur_description/urdf/ur5_robot.urdf"
    if urdf is None or not urdf.exists():
        return None
    # the NLP's collision rows model boxes and capsules: each collision mesh becomes its bounding box
    return RobotModel.from_urdf(collision_meshes_as_boxes(urdf, package_dirs=[share]), arms={"A": "tool0"},
                                name="ur5")


def ur5_box() -> None:
    r = _ur5()
    if r is None:
        print("3. UR5: example-robot-data is not installed (pip install 'optplan[robots]'); skipped")
        return
    print("3. UR5 past one box, margin 0.02 m, N = 10")
    q0 = np.array([-1.2, -1.2, 1.5, -1.9, -1.57, 0.0])
    q1 = np.array([1.2, -1.2, 1.5, -1.9, -1.57, 0.0])
    pin.framesForwardKinematics(r.model, r.data, (q0 + q1) / 2)
    pm = r.data.oMf[r.frame_id("tool0")].translation
    c = np.r_[pm[:2] + 0.09 * pm[:2] / np.linalg.norm(pm[:2]), pm[2]]
    scene = Scene("ur5_box", None, (Obstacle("box", "box", pin.SE3(np.eye(3), c), size=(0.1, 0.1, 0.3)),))
    for how in ("solve_knots", "solve"):
        z = np.zeros(6)
        prob = OptProblem(r, n_intervals=10, duration=3.0)
        prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
        prob.add_constraint(JointBoundary("end", q=q1, qd=z, qdd=z))
        prob.add_cost(Smoothness("jerk"))
        prob.add_constraint(CollisionAvoidance(scene, margin=0.02, self_collision=False))
        prob.set_initial_straight_line(q0, q1)
        t0 = time.perf_counter()
        sol = getattr(prob, how)()
        dt = time.perf_counter() - t0
        rep = verify(r, sol, scene)
        v = check_between_knots(prob, sol)
        print(f"   {how:11s} success={sol.success}  N={prob.N}  iterations {sol.total_iterations} "
              f"({[a.label or 'first' for a in sol.attempts]})  {dt:.2f} s  clearance {rep.min_clearance_m:.4f} m "
              f"({rep.min_clearance_pair}); dense check: {v[0] if v else 'no violation'}")


def random_boxes(M: int, seed: int = 0) -> None:
    from optplan.collision.checker import CollisionChecker

    print(f"4. {M} random problems (tcbirrt_dual_arm arm A past a random box, random margin, N = 6)")
    r = RobotModel.from_name("tcbirrt_dual_arm")
    rng = np.random.default_rng(seed)
    qa = r.neutral()
    qb = qa.copy()
    qb[:3] += np.array([0.6, -0.4, 0.5])
    counts = {"knots: success": 0, "knots: success, margin missed": 0, "solve: success": 0,
              "solve: success, margin missed": 0, "solve: violated_between_knots": 0, "solve: other failure": 0}
    its = {"knots": 0, "solve": 0}
    done = 0
    while done < M:
        offset, side, size = rng.uniform(0, 0.12), rng.uniform(0, 2 * np.pi), rng.uniform(0.04, 0.12)
        margin, frac = rng.uniform(0.005, 0.04), rng.uniform(0.3, 0.7)
        pin.framesForwardKinematics(r.model, r.data, qa + frac * (qb - qa))
        p = r.data.oMf[r.arm("A").ee_frame_id].translation
        c = p + (offset + size / 2) * np.array([np.cos(side), np.sin(side), 0.0])
        scene = Scene("box", None, (Obstacle("box", "box", pin.SE3(np.eye(3), c), size=(size, size, size)),))
        checker = CollisionChecker(r, scene, self_collision=False)
        if min(checker.distances(qa).min(), checker.distances(qb).min()) <= margin + 0.01:
            continue   # the given ends inside the margin: nothing can succeed
        done += 1
        for how in ("knots", "solve"):
            z = np.zeros(r.nj)
            prob = OptProblem(r, n_intervals=6, duration=2.0)
            prob.add_constraint(JointBoundary("start", q=qa, qd=z, qdd=z))
            prob.add_constraint(JointBoundary("end", q=qb, qd=z, qdd=z))
            prob.add_cost(Smoothness("jerk"))
            prob.add_constraint(CollisionAvoidance(scene, margin=margin, self_collision=False))
            prob.set_initial_straight_line(qa, qb)
            sol = prob.solve_knots(max_iter=200) if how == "knots" else prob.solve(max_iter=200)
            its[how] += sol.total_iterations
            ts = np.linspace(0.0, sol.duration, 10 * (len(sol.t) - 1) + 1)
            missed = checker.min_distance_along(sol.sample(ts)["q"])[0] < margin - (1e-3 + 1e-3 * margin)
            if sol.success:
                counts[f"{how}: success"] += 1
                counts[f"{how}: success, margin missed"] += int(missed)
            elif how == "solve":
                counts["solve: violated_between_knots" if sol.between_knots else "solve: other failure"] += 1
    for k, v in counts.items():
        print(f"   {k:32s} {v}")
    print(f"   IPOPT iterations in total: knots {its['knots']}, solve {its['solve']}")


def transport() -> None:
    from optplan.collision.checker import CollisionChecker
    from optplan.tasks import transport_initial_path, transport_problem

    print("5. closed-chain transport, knot transcription, N = 50, margin 0.02 m")
    robot, scene = RobotModel.from_name("tcbirrt_dual_arm"), Scene.load("transport")
    Q = transport_initial_path(robot, scene, 50, np.random.default_rng(0), checker=CollisionChecker(robot, scene))
    for how in ("solve_knots", "solve"):
        prob, cc, _ = transport_problem(robot, scene, Q, duration=60.0, margin=0.02)
        t0 = time.perf_counter()
        sol = getattr(prob, how)()
        dt = time.perf_counter() - t0
        t1 = time.perf_counter()
        v = check_between_knots(prob, sol)
        tc = time.perf_counter() - t1
        rep = verify(robot, sol, scene, closed_chain=cc)
        print(f"   {how:11s} success={sol.success}  iterations {sol.total_iterations} "
              f"({[a.label or 'first' for a in sol.attempts]})  {dt:.2f} s  clearance {rep.min_clearance_m:.4f} m "
              f"({rep.min_clearance_pair}); dense check {tc:.3f} s: {v[0] if v else 'no violation'}")


if __name__ == "__main__":
    rnea_accuracy(np.random.default_rng(0))
    torque_move()
    if "--skip-ur5" not in sys.argv:
        ur5_box()
    if "--transport" in sys.argv:
        transport()
    if "--random" in sys.argv:
        random_boxes(int(sys.argv[sys.argv.index("--random") + 1]))
