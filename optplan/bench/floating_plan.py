"""Planning with a drifting base: the floating planners on the shipped floating scenes and on
generated cases, each trial classified by an independent reachability test of its goal.

``python -m optplan.bench.floating_plan --scene floating_truss,floating_stow --trials 100 --generated 40 --out F``

* Shipped scenes: start = the scene's witness ``[extra] q_start``, goal = ``trial_goal(scene, i, seed)``
  (as ``optplan bench generalize --scene floating`` draws them), the scene's goal frame.
* Generated cases (world goal): the ``floating_truss`` robot and module, a start pose of the module
  drawn around the scene's start (joints by path IK from the witness), a goal pose drawn around the
  start, and 1-3 random boxes around the start-goal segment (none touching the robot at the start,
  nor the module at its start or goal pose).
* Every trial is run by each planner (``tcbirrt``: :class:`~optplan.planners.floating_tcbirrt.FloatingTCBiRRT`;
  ``carry``: :class:`~optplan.planners.floating_carry.FloatingCarryPlanner`) with the same time
  limit; success = an ``exact`` plan within ``--time-limit`` CPU seconds.
* Reachability of a world goal (:func:`world_reachable`): with zero momentum the system's centre
  of mass stays where it is, so the base position follows from the joints and the base attitude; a
  goal is reachable when some joints and attitude put both hands at their grasps on the module at
  the goal with the centre of mass unmoved (:func:`~optplan.planners.floating_reach.zero_momentum_ik`
  from 13 seeds, residual ≤ 1e-9).
  A trial whose goal is not is reported as "unreachable" (no planner can solve it); the search is
  local, so "unreachable" is evidence, not proof. A base-frame goal is reachable when the two-arm
  IK has a collision-free solution.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

__all__ = ["world_reachable", "arrival_diagnosis", "generated_case", "run_trial", "main"]


def world_reachable(planner, goal: pin.SE3, seeds: list[np.ndarray], rng: np.random.Generator,
                    base0: pin.SE3 | None = None, n_random: int = 12) -> tuple[bool, float]:
    """Whether some joints and base attitude hold the module at the world ``goal`` with the centre
    of mass where it is at ``(seeds[0], base0)``
    (:func:`~optplan.planners.floating_reach.zero_momentum_ik`); returns (reachable, smallest
    residual [m, rad] found)."""
    from ..planners.floating_reach import zero_momentum_ik

    base0 = pin.SE3.Identity() if base0 is None else base0
    robot = planner.robot
    com = pin.centerOfMass(robot.model, robot.model.createData(), planner.carry._full(seeds[0], base0))
    _, _, res = zero_momentum_ik(robot, planner.carry.grasps, goal, seeds, com, rng, attitude=base0,
                                 n_random=n_random, iters=150)
    return bool(res <= 1e-9), float(res)


def arrival_diagnosis(planner, goal: pin.SE3, q0: np.ndarray, seed: int) -> dict:
    """Of a failed world-goal query, the first join that reached the goal tree's root: the object's
    miss there (position [m], rotation [rad]), whether the zero-momentum IK holds the module at the
    goal with the base attitude HELD at that arrival attitude (its residual [m, rad]), and how far
    [rad] from the arrival the attitude of a free zero-momentum IK solution lies. Not reachable with
    the attitude held: the joined paths arrive at an attitude from which no closed-chain correction
    lands the goal; only a path that turns the base otherwise can."""
    from ..planners.floating_reach import zero_momentum_ik

    q, b = planner.first_arrival
    robot = planner.robot
    com = pin.centerOfMass(robot.model, robot.model.createData(), planner.carry._full(q0))
    _, _, r_held = zero_momentum_ik(robot, planner.carry.grasps, goal, [q], com, np.random.default_rng(seed),
                                    attitude=b, n_random=8, fix_attitude=True)
    _, bf, r_free = zero_momentum_ik(robot, planner.carry.grasps, goal, [q], com, np.random.default_rng(seed),
                                     attitude=b, n_random=8)
    ep, er = planner.carry._goal_error(q, b, goal)
    return {"miss_m": ep, "miss_rad": er, "held_residual": float(r_held), "held_reachable": bool(r_held <= 1e-9),
            "free_residual": float(r_free), "free_attitude_gap_rad": float(np.linalg.norm(pin.log3(b.rotation.T @ bf.rotation)))}


def generated_case(robot, base_scene, rng: np.random.Generator):
    """(scene, q_start, goal) of a generated case (module docstring), or None when the draw fails."""
    from ..collision.checker import CollisionChecker
    from ..planners.floating_tcbirrt import FloatingTCBiRRT
    from ..scene import Obstacle
    from ..trials import perturb_pose

    free = dataclasses.replace(base_scene, obstacles=())
    pl = FloatingTCBiRRT(robot, free)
    witness = np.radians(np.asarray(base_scene.extra["q_start"], float))
    start = perturb_pose(base_scene.start, rng, 0.1, 0.2)
    q0 = pl._path_ik(witness, start)
    if q0 is None or not pl.validity.is_valid(pl.carry._full(q0)):
        return None
    goal = perturb_pose(start, rng, 0.4, 0.4)
    obj = base_scene.object.coal_geometry()
    import coal

    obstacles: list = []
    mid = 0.5 * (start.translation + goal.translation)
    for k in range(int(rng.integers(1, 4))):
        for _ in range(50):
            beam = rng.uniform() < 0.5
            size = (0.15, 0.15, 3.0) if beam else tuple(rng.uniform(0.1, 0.3, 3))
            R = pin.rpy.rpyToMatrix(*(rng.uniform(-0.5, 0.5, 3) if beam else rng.uniform(-np.pi, np.pi, 3)))
            ob = Obstacle(f"gen_{k}", "box", pin.SE3(R, mid + rng.uniform(-0.8, 0.8, 3)), size=size)
            g = ob.coal_geometry()
            req, res = coal.DistanceRequest(), coal.DistanceResult()
            clear = min(coal.distance(obj, coal.Transform3s(M.rotation, M.translation), g,
                                      coal.Transform3s(ob.placement.rotation, ob.placement.translation), req, res)
                        for M in (start, goal))
            if clear < 0.05:
                continue
            trial = dataclasses.replace(free, obstacles=tuple(obstacles) + (ob,))
            if CollisionChecker(robot, trial).min_distance(pl.carry._full(q0))[0] >= 0.02:
                obstacles.append(ob)
                break
    return dataclasses.replace(free, name=f"generated_{int(rng.integers(1 << 30))}", obstacles=tuple(obstacles),
                               start=start, goal=goal, extra={**free.extra, "target_frame": "world"}), q0, goal


def run_trial(robot, scene, q0: np.ndarray, goal: pin.SE3, seed: int, time_limit: float, frame: str,
              planners: tuple[str, ...] = ("tcbirrt", "carry"), restore: bool = False) -> dict:
    """Each of ``planners`` on one query, and the goal's reachability. ``restore``: ``tcbirrt`` ends
    with the base at its initial attitude (``FloatingTreeOptions.restore_attitude``); the row then
    has the plan's final attitude error [rad]."""
    from ..planners.floating_carry import FloatingCarryOptions, FloatingCarryPlanner
    from ..planners.floating_tcbirrt import FloatingTCBiRRT, FloatingTreeOptions

    opts = FloatingCarryOptions(target_frame=frame)
    tcb = FloatingTCBiRRT(robot, scene, opts, FloatingTreeOptions(restore_attitude=restore))
    row: dict = {"seed": seed}
    for name, planner in (("tcbirrt", tcb), ("carry", FloatingCarryPlanner(robot, scene, opts))):
        if name not in planners:
            continue
        c0 = time.process_time()
        res = planner.plan(q0, goal, seed=seed, time_limit=time_limit)
        cpu = time.process_time() - c0
        row[name] = {"status": res.status.value, "cpu_s": cpu, "ok": bool(res.success and cpu <= time_limit),
                     "waypoints": len(res.joints), "corrections": res.corrections, "message": res.message[:300],
                     **({"stats": dict(tcb.stats)} if name == "tcbirrt" else {}),
                     "final_attitude_rad": float(np.linalg.norm(pin.log3(res.final_base.rotation))),
                     "goal_error": list(res.goal_error)}
    if frame == "world" and "tcbirrt" in row and not row["tcbirrt"]["ok"] and tcb.first_arrival is not None:
        row["tcbirrt"]["arrival"] = arrival_diagnosis(tcb, goal, q0, seed)
    if frame == "world":
        ok, resid = world_reachable(tcb, goal, [q0], np.random.default_rng(seed))
    else:
        from ..planners.base import Deadline

        ok = tcb._goal_joints([q0], goal, pin.SE3.Identity(), np.random.default_rng(seed), Deadline(30.0)) is not None
        resid = 0.0 if ok else math.nan
    row["reachable"], row["reach_residual"] = bool(ok), resid
    return row


def main(argv: list[str] | None = None) -> None:
    from ..floating_pipeline import options_for_scene, scene_start, trial_goal
    from ..model.robot import RobotModel
    from ..scene import Scene

    ap = argparse.ArgumentParser(prog="python -m optplan.bench.floating_plan", description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="floating_truss,floating_stow")
    ap.add_argument("--trials", type=int, default=100, help="trials per shipped scene [count]")
    ap.add_argument("--first-trial", type=int, default=0)
    ap.add_argument("--generated", type=int, default=0, help="generated cases [count]")
    ap.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds per query [s]")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--planners", default="tcbirrt,carry", help="comma-separated: tcbirrt, carry")
    ap.add_argument("--restore", action="store_true",
                    help="tcbirrt ends with the base at its initial attitude (world goals)")
    ap.add_argument("--out", required=True, help="results (JSON lines), appended")
    a = ap.parse_args(argv)
    planners = tuple(p for p in a.planners.split(",") if p)
    if not planners or any(p not in ("tcbirrt", "carry") for p in planners):
        ap.error(f"--planners: expected a comma-separated subset of tcbirrt,carry, got {a.planners!r}")
    robot = RobotModel.from_name("eba_ffsr")
    out = Path(a.out)
    with out.open("a") as f:
        for name in [s for s in a.scene.split(",") if s]:
            scene = Scene.load(name)
            frame = options_for_scene(scene).planner.target_frame
            q0 = scene_start(robot, scene)
            for i in range(a.first_trial, a.first_trial + a.trials):
                row = run_trial(robot, scene, q0, trial_goal(scene, i, a.seed), a.seed + i, a.time_limit, frame,
                                planners, a.restore)
                f.write(json.dumps({"case": name, "trial": i, **row}) + "\n")
                f.flush()
        rng = np.random.default_rng(a.seed)
        base = Scene.load("floating_truss")
        made = 0
        while made < a.generated:
            case = generated_case(robot, base, rng)
            if case is None:
                continue
            scene, q0, goal = case
            row = run_trial(robot, scene, q0, goal, a.seed + made, a.time_limit, "world", planners, a.restore)
            row["obstacles"] = len(scene.obstacles)
            f.write(json.dumps({"case": "generated", "trial": made, **row}) + "\n")
            f.flush()
            made += 1


if __name__ == "__main__":
    main()
