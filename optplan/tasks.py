"""Task helpers shared by the examples, the pipeline and the benchmarks: grasp configurations of
a held object, task-space paths mapped through IK, and the closed-chain transport problem."""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from .collision.checker import CollisionChecker
from .constraints.closed_chain import solve_grasp_ik
from .geometry.spatial import interpolate_pose
from .model.ik import IKOptions
from .model.robot import RobotModel
from .problem import (
    ClosedChain,
    CollisionAvoidance,
    JointBoundary,
    JointPositionLimits,
    JointVelocityLimits,
    OptProblem,
    Smoothness,
)
from .scene import Scene
from .scene import held_object as _held_object

__all__ = ["GraspIK", "grasp_configuration", "task_space_path", "transport_initial_path", "transport_problem",
           "segment_problem", "object_pose"]
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
    grasps = _held_object(scene).grasps
    for M in poses[1:]:
        r = solve_grasp_ik(robot, M, grasps, qs[-1], opts, data)
        ok &= r.success
        qs.append(r.q)
    return np.array(qs), bool(ok)


def object_pose(robot: RobotModel, scene: Scene, q, arm: str, data: pin.Data | None = None) -> pin.SE3:
    """World pose of the scene's object held by ``arm``'s hand at the full configuration ``q``."""
    data = data or robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, np.asarray(q, float))
    return _held_object(scene).object_pose_from_hand(arm, data.oMf[robot.arm(arm).ee_frame_id])


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


def segment_problem(robot: RobotModel, scene: Scene, q_start, q_end, n_intervals: int, duration: float, *,
                    closed_chain: ClosedChain | None = None, joint_limits=None, velocity_limits: bool = True,
                    collision: bool = True, margin: float = 0.02, object_arm: str | None = None,
                    fixed_normals: bool | None = None, end_name: str = "end", transcription: str = "knots",
                    velocity_activation: float | None = None) -> tuple[OptProblem, CollisionAvoidance | None]:
    """The rest-to-rest NLP of one path segment: ``q_start`` → ``q_end`` at rest on
    ``n_intervals`` intervals over ``duration`` [s]; the ``closed_chain`` (when given), joint
    position limits (``joint_limits``: ``(lower, upper)`` [rad], default the robot's), joint
    velocity limits, collision avoidance with ``margin`` [m] (object held by ``object_arm``; plane
    normals fixed when ``fixed_normals``), minimum jerk. The one builder of the transport NLP of
    the examples and of the pipeline's segments; returns ``(problem, collision term or None)``.
    ``velocity_activation``: :attr:`JointVelocityLimits.activation` [fraction of the limit]."""
    z = [0.0] * robot.nj
    # the knot transcription by default: the pipeline's fallback is tuned on it (its retries change
    # the collision term's pairs and normals; docs/decisions/0016-modelling-on-the-kernel-core.md)
    prob = OptProblem(robot, n_intervals=n_intervals, duration=duration, transcription=transcription)
    prob.add_constraint(JointBoundary("start", q=q_start, qd=z, qdd=z), name="start")
    prob.add_constraint(JointBoundary("end", q=q_end, qd=z, qdd=z), name=end_name)
    if closed_chain is not None:
        prob.add_constraint(closed_chain, name="closed_chain")
    lo, hi = joint_limits if joint_limits is not None else (None, None)
    prob.add_constraint(JointPositionLimits(lower=lo, upper=hi), name="joint_limits")
    if velocity_limits:
        prob.add_constraint(JointVelocityLimits(activation=velocity_activation), name="velocity_limits")
    col = None
    if collision:
        kw: dict[str, Any] = {} if fixed_normals is None else {"fixed_normals": fixed_normals}
        if object_arm is not None:
            kw["object_arm"] = object_arm
        col = CollisionAvoidance(scene, margin=margin, **kw)
        prob.add_constraint(col, name="collision")
    prob.add_cost(Smoothness("jerk"), name="jerk")
    return prob, col


def transport_problem(robot: RobotModel, scene: Scene, Q: np.ndarray, *, duration: float = 60.0,
                      margin: float = 0.02, velocity_limits: bool = True, collision: bool = True,
                      fixed_normals: bool | None = None, transcription: str = "knots"
                      ) -> tuple[OptProblem, ClosedChain, CollisionAvoidance | None]:
    """The closed-chain transport NLP on ``len(Q) − 1`` intervals (:func:`segment_problem`):
    boundary configurations of Q at rest, closed chain from the scene's grasps, joint position
    (and velocity) limits, collision avoidance with ``margin`` [m], minimum jerk; warm-started
    from Q."""
    grasps = _held_object(scene).grasps
    arms = list(grasps)
    cc = ClosedChain.from_grasps(grasps[arms[0]], grasps[arms[1]], arms[0], arms[1])
    prob, col = segment_problem(robot, scene, Q[0], Q[-1], len(Q) - 1, duration, closed_chain=cc,
                                velocity_limits=velocity_limits, collision=collision, margin=margin, end_name="goal",
                                fixed_normals=fixed_normals, transcription=transcription)
    prob.set_initial(q=Q)
    return prob, cc, col
