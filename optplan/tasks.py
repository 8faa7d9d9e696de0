"""Task helpers shared by the examples, the pipeline and the benchmarks: grasp configurations of
a held object, task-space paths mapped through IK, and the closed-chain transport problem."""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .collision import CollisionChecker
from .ik import IKOptions, solve_grasp_ik
from .problem import (ClosedChain, CollisionAvoidance, JointBoundary, JointPositionLimits, JointVelocityLimits,
                      OptProblem, Smoothness)
from .robot import RobotModel
from .scene import Scene
from .spatial import interpolate_pose

__all__ = ["GraspIK", "grasp_configuration", "task_space_path", "transport_initial_path", "transport_problem"]
log = logging.getLogger(__name__)

_PRECISE = IKOptions(tol_position=1e-10, tol_orientation=1e-10, max_iterations=300)


@dataclass(frozen=True)
class GraspIK:
    """Result of :func:`grasp_configuration`: ``q`` (None when not found), clearance [m], tries."""

    q: np.ndarray | None
    clearance: float
    tries: int

    @property
    def found(self) -> bool:
        return self.q is not None


def grasp_configuration(robot: RobotModel, scene: Scene, object_pose: pin.SE3, rng: np.random.Generator, *,
                        min_clearance: float = 0.05, tries: int = 300, checker: CollisionChecker | None = None,
                        options: IKOptions = _PRECISE) -> GraspIK:
    """A collision-free configuration with every hand on its grasp of the object at
    ``object_pose``: closed-chain IK from random seeds until one has ``min_clearance`` [m]
    (exact coal distance, object included)."""
    if scene.object is None:
        raise ValueError(f"scene {scene.name!r} has no [object] with grasps")
    checker = checker or CollisionChecker(robot, scene)
    best_d = -np.inf
    for i in range(1, tries + 1):
        res = solve_grasp_ik(robot, object_pose, scene.object.grasps, robot.random_configuration(rng), options)
        if not res.success:
            continue
        d = checker.min_distance(res.q)[0]
        best_d = max(best_d, d)
        if d >= min_clearance:
            return GraspIK(res.q, d, i)
    return GraspIK(None, best_d, tries)


def task_space_path(robot: RobotModel, scene: Scene, q_start, poses, *, max_step: float = 0.05,
                    options: IKOptions = _PRECISE) -> tuple[np.ndarray, bool]:
    """Map object poses through closed-chain IK, each seeded by the previous solution
    (the TCBiRRT paper's PathInverseKinematics). Returns (M × nq configurations, all converged)."""
    opts = IKOptions(options.tol_position, options.tol_orientation, options.max_iterations,
                     options.damping, max_step, options.respect_limits)
    qs, ok = [np.asarray(q_start, float)], True
    data = robot.model.createData()
    for M in poses[1:]:
        r = solve_grasp_ik(robot, M, scene.object.grasps, qs[-1], opts, data)
        ok &= r.success
        qs.append(r.q)
    return np.array(qs), bool(ok)


def straight_line_poses(start: pin.SE3, goal: pin.SE3, n: int) -> list[pin.SE3]:
    """``n + 1`` object poses from start to goal: position linear, orientation in exponential
    coordinates (the TCBiRRT paper Eq. 4)."""
    return [interpolate_pose(start, goal, k / n) for k in range(n + 1)]


def transport_initial_path(robot: RobotModel, scene: Scene, knots: int, rng: np.random.Generator, *,
                           checker: CollisionChecker | None = None, attempts: int = 20) -> np.ndarray | None:
    """The transport problem's initial guess: a collision-free start grasp (:func:`grasp_configuration`)
    whose straight-line object path (:func:`straight_line_poses`, ``knots`` intervals) maps through
    closed-chain IK to a collision-free goal grasp; ``(knots + 1) × nq`` configurations, or None
    when none of ``attempts`` start grasps gives one."""
    checker = checker or CollisionChecker(robot, scene)
    for _ in range(int(attempts)):
        start = grasp_configuration(robot, scene, scene.start, rng, checker=checker)
        if not start.found:
            return None
        Q, ok = task_space_path(robot, scene, start.q, straight_line_poses(scene.start, scene.goal, knots))
        if ok and checker.min_distance(Q[-1])[0] > 0.0:
            return Q
    return None


def transport_problem(robot: RobotModel, scene: Scene, Q: np.ndarray, *, duration: float = 60.0,
                      margin: float = 0.02, velocity_limits: bool = True,
                      collision: bool = True) -> tuple[OptProblem, ClosedChain, CollisionAvoidance | None]:
    """The closed-chain transport NLP on ``len(Q) − 1`` intervals: boundary configurations of Q at
    rest, closed chain from the scene's grasps, joint position (and velocity) limits, collision
    avoidance with ``margin`` [m], minimum jerk; warm-started from Q."""
    N = len(Q) - 1
    z = np.zeros(robot.nj)
    prob = OptProblem(robot, n_intervals=N, duration=duration)
    prob.add_constraint(JointBoundary("start", q=Q[0], qd=z, qdd=z), name="start")
    prob.add_constraint(JointBoundary("end", q=Q[-1], qd=z, qdd=z), name="goal")
    arms = list(scene.object.grasps)
    cc = ClosedChain.from_grasps(scene.object.grasps[arms[0]], scene.object.grasps[arms[1]], arms[0], arms[1])
    prob.add_constraint(cc, name="closed_chain")
    prob.add_constraint(JointPositionLimits(), name="joint_limits")
    if velocity_limits:
        prob.add_constraint(JointVelocityLimits(), name="velocity_limits")
    col = None
    if collision:
        col = CollisionAvoidance(scene, margin=margin)
        prob.add_constraint(col, name="collision")
    prob.add_cost(Smoothness("jerk"), name="jerk")
    prob.set_initial(q=Q)
    return prob, cc, col
