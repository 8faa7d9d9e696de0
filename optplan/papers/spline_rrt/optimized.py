"""optplan's optimized variant of the Spline-RRT* task (:func:`optimize`): the hand paths as
constraints on the free-floating robot, the links apart, the base attitude restored at the end.

Two transcriptions of the same task (``OptimizeOptions.transcription``):

* ``"bspline"`` (default): an :class:`~optplan.problem.OptProblem` on the B-spline kernel core.
  The hand paths are per-point expressions of ``prob.frame(ee)`` against the path sampled at the
  knots (a parameter, selected at each knot by the hat function of ``prob.t``); the goal
  orientation an expression at the end; the joint-rate limit holds everywhere by the convex hull
  of the velocity control points, so no interior samples are needed.
* ``"knots"``: the knot transcription with two custom terms (:class:`EndOrientation`,
  :class:`InteriorVelocityLimits`: the rate sampled inside every interval), kept as the measured
  comparison.

See docs/decisions/0022-papers-on-the-shared-core.md for the measured comparison.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from ...errors import OptionError
from ...model.robot import RobotModel
from ...problem.terms import Term, pose_residual, pose_residual_numeric
from .tracking import TrackingResult

__all__ = ["OptimizeOptions", "EndOrientation", "InteriorVelocityLimits", "optimize", "knot_selector"]


@dataclass
class EndOrientation(Term):
    """A frame's world orientation at the last knot equals ``target`` (3 × 3): ``FramePose``
    without its position rows, which would repeat the last ``FramePath`` position rows and make
    the equality Jacobian rank-deficient. Residual and bounds as ``FramePose``."""

    frame: str = ""
    target: np.ndarray | None = None
    default_name = "end_orientation"

    def residual(self, tp):
        R, p = tp.frame(self.frame, tp.N)
        r, tr = pose_residual(R, p, np.asarray(self.target, float), p)
        return ca.vertcat(r[3:], tr), np.r_[0.0, 0.0, 0.0, 1.0], np.r_[0.0, 0.0, 0.0, np.inf]

    def numeric(self, traj):
        M = traj.frame(self.frame, traj.N)
        r, tr = pose_residual_numeric(M, pin.SE3(np.asarray(self.target, float), M.translation))
        return np.r_[r[3:], tr]

    def bounds_numeric(self, traj):
        return np.r_[0.0, 0.0, 0.0, 1.0], np.r_[0.0, 0.0, 0.0, np.inf]


@dataclass
class InteriorVelocityLimits(Term):
    """``|q̇| ≤ scale · robot.velocity_limit`` [rad/s] at the interior fractions ``fractions`` of every
    interval (``JointVelocityLimits`` holds at the knots only; q̇ is quadratic between them and
    overshoots the limit between knots without this term). See docs/decisions/0011-paper-reproduction-grids-and-guards.md."""

    fractions: tuple = (1 / 6, 1 / 3, 1 / 2, 2 / 3, 5 / 6)
    scale: float = 1.0
    default_name = "interior_velocity_limits"

    def residual(self, tp):
        lim = self.scale * tp.robot.velocity_limit
        rows = []
        for k in range(tp.N):
            for f in self.fractions:
                tau = f * tp.h
                rows.append(tp.qd(k) + tau * tp.qdd(k) + tau ** 2 / 2 * tp.jerk(k))
        n = len(rows)
        return ca.vertcat(*rows), np.tile(-lim, n), np.tile(lim, n)

    def numeric(self, traj):
        out = []
        for k in range(traj.N):
            for f in self.fractions:
                tau = f * traj.h
                out.append(traj.qd[k] + tau * traj.qdd[k] + tau ** 2 / 2 * traj.jerk[k])
        return np.concatenate(out)

    def bounds_numeric(self, traj):
        n = traj.N * len(self.fractions)
        lim = self.scale * traj.robot.velocity_limit
        return np.tile(-lim, n), np.tile(lim, n)


@dataclass(frozen=True)
class OptimizeOptions:
    """Options of the optimized variant (:func:`optimize`)."""

    #: N: intervals of the grid [count].
    n_intervals: int = 30
    #: RK4 sub-steps of the base per interval [count].
    n_sub: int = 2
    #: Its duration is this times the Spline-RRT* duration [-] (> 1: the same hand paths run slower, leaving the
    #: joint-rate limits room for the self-motion that restores the attitude).
    duration_factor: float = 1.5
    #: Joint acceleration limit at the knots [rad/s²] (q̈ is piecewise linear).
    joint_accel_limit: float = 0.1
    #: The NLP's joint-rate limits are this times the robot's [-] (the interior points sample the rate, and the
    #: executed motion deviates slightly from the NLP's between knots).
    rate_margin: float = 0.995
    #: Clearance between the robot's links [m].
    link_margin: float = 0.1
    #: Clearance to the obstacles [m].
    obstacle_margin: float = 0.0
    #: Base attitude at T equal to the start's as a hard constraint (False: minimised as a cost).
    restore_attitude: bool = True
    #: Hand paths as position constraints with the orientation constrained at the goal only (False: full poses
    #: at every knot).
    position_only: bool = True
    #: Weight of the squared deviation from the Bézier orientation (a cost, with ``position_only``) [1/rad²].
    orientation_weight: float = 1.0
    #: IPOPT's constraint tolerance [-].
    tol: float = 1e-8
    #: IPOPT iterations, at most [count].
    max_iter: int = 300
    #: ``"bspline"`` (default): the B-spline kernel core (joint velocity limits hold everywhere by the convex
    #: hull of the velocity control points, the hand paths as per-point expressions); ``"knots"``: the knot
    #: transcription (the state at every knot, the rate limits sampled inside the intervals).
    transcription: str = "bspline"

    def __post_init__(self):
        if self.transcription not in ("bspline", "knots"):
            raise OptionError(f"OptimizeOptions.transcription: expected 'bspline' or 'knots', got {self.transcription!r}")
        if isinstance(self.n_intervals, bool) or not isinstance(self.n_intervals, (int, np.integer)) \
                or self.n_intervals < 4:
            raise OptionError(f"OptimizeOptions.n_intervals: expected an integer ≥ 4, got {self.n_intervals!r}")



def optimize(robot: RobotModel, task: Any, hands: dict, T: float, warm: TrackingResult,
             options: OptimizeOptions | None = None):
    """The Spline-RRT* task (``task``: a :class:`~optplan.papers.spline_rrt.SplineRRTTask`) as an
    :class:`~optplan.problem.OptProblem` on the floating base (base at the origin, zero momentum),
    warm-started from the tracked joint trajectory ``warm``: hands on their planned paths at every
    knot, start at rest from ``task.q_start``, rest at T [s], joint position/velocity/acceleration
    limits, link–link distance ≥ ``link_margin`` and clearance to the obstacles, base attitude
    restored at T, minimum jerk. Returns ``(Solution, OptProblem)``."""
    o = options or OptimizeOptions()
    prob = _spline_problem(robot, task, hands, T, o) if o.transcription == "bspline" else \
        _knot_problem(robot, task, hands, T, o)
    prob.set_initial(q=warm.joints, t=warm.t)
    # the B-spline builder's hand paths are per-knot samples (a parameter on this grid): a refined
    # grid would read them at the wrong knots, so no dense check there; the executed motion is judged
    sol = prob.solve(tol=o.tol, max_iter=o.max_iter, guarantees=o.transcription != "bspline")
    return sol, prob


def knot_selector(t: Any, T: Any, N: int) -> Any:
    """``(N+1) × 1`` weights of the knots at time ``t`` [s] of a grid of N intervals over ``T`` [s]:
    the hat functions ``max(0, 1 − |t·N/T − k|)`` — one at knot k, zero at the others (a
    parameter ``P`` (m × (N+1)) of per-knot values gives ``P @ w``, the value of the point's knot)."""
    u = t * N / T
    return ca.vertcat(*[ca.fmax(0, 1 - ca.fabs(u - k)) for k in range(N + 1)])


def _attitude_and_limits(prob: Any, robot: RobotModel, o: OptimizeOptions) -> None:
    """The base attitude at the end (restored: a constraint; else a cost of weight 1e4) and the
    joint position and velocity limits (velocity: ``rate_margin`` × the robot's), in this order."""
    from ...problem import BaseAttitude, JointPositionLimits, JointVelocityLimits

    if o.restore_attitude:
        prob.add_constraint(BaseAttitude(at="end"))
    else:
        prob.add_cost(BaseAttitude(at="end"), weight=1e4)
    prob.add_constraint(JointPositionLimits())
    prob.add_constraint(JointVelocityLimits(limit=o.rate_margin * robot.velocity_limit))


def _common(prob: Any, robot: RobotModel, task: Any, o: OptimizeOptions) -> None:
    """The terms both transcriptions share (boundary, attitude, limits, collision, jerk)."""
    from ...problem import (
        JointAccelerationLimits,
        JointBoundary,
        Smoothness,
    )

    zero = np.zeros(robot.nj)
    prob.add_constraint(JointBoundary("start", q=task.q_start, qd=zero, qdd=zero))
    prob.add_constraint(JointBoundary("end", qd=zero))
    _attitude_and_limits(prob, robot, o)
    prob.add_constraint(JointAccelerationLimits(limit=o.joint_accel_limit))
    prob.add_cost(Smoothness("jerk"))


def _spline_problem(robot: RobotModel, task: Any, hands: dict, T: float, o: OptimizeOptions) -> Any:
    from ...problem import CollisionAvoidance, OptProblem

    N = o.n_intervals
    prob = OptProblem(robot, N, T, n_sub=o.n_sub, transcription="bspline")
    _common(prob, robot, task, o)
    w = knot_selector(prob.t, prob.T, N)
    tk = np.linspace(0.0, T, N + 1)
    for a, h in hands.items():
        fr = prob.frame(robot.arm(a).ee_frame)
        poses = [h.pose(t) for t in tk]
        P = prob.parameter((3, N + 1), np.array([M.translation for M in poses]).T)
        if o.position_only:
            prob.add_constraint(fr.translation - P @ w, lower=0.0, upper=0.0, name=f"path_{a}")
            r, tr = pose_residual(fr.rotation, fr.translation, poses[-1].rotation, fr.translation)
            prob.add_constraint(ca.vertcat(r[3:], tr), lower=np.r_[0.0, 0.0, 0.0, 1.0],
                                upper=np.r_[0.0, 0.0, 0.0, np.inf], at="end", name=f"goal_orientation_{a}")
            if o.orientation_weight > 0:
                # Σ_k ‖vee(R_kᵀ R)‖² at the knots (the knot variant's FramePath cost), as an integral
                # of weight N/T (the trapezoid halves only the pinned start, a constant)
                Rp = prob.parameter((9, N + 1), np.array([M.rotation.ravel(order="F") for M in poses]).T)
                Rt = ca.reshape(Rp @ w, 3, 3)
                r, tr = pose_residual(fr.rotation, fr.translation, Rt, fr.translation)
                prob.add_cost(r[3:], weight=o.orientation_weight * N / T, name=f"orientation_{a}")
        else:
            Rp = prob.parameter((9, N + 1), np.array([M.rotation.ravel(order="F") for M in poses]).T)
            r, tr = pose_residual(fr.rotation, fr.translation, ca.reshape(Rp @ w, 3, 3), P @ w)
            prob.add_constraint(ca.vertcat(r, tr), lower=np.r_[np.zeros(6), 1.0], upper=np.r_[np.zeros(6), np.inf],
                                name=f"path_{a}")
    prob.add_constraint(CollisionAvoidance(None, margin=o.link_margin, self_collision=True, held_object=False,
                                           fixed_normals=True), name="links")
    if task.scene.obstacles:
        prob.add_constraint(CollisionAvoidance(task.scene, margin=o.obstacle_margin, self_collision=False,
                                               held_object=False, fixed_normals=True), name="obstacles")
    return prob


def _knot_problem(robot: RobotModel, task: Any, hands: dict, T: float, o: OptimizeOptions) -> Any:
    """The reproduction as first measured (the term order kept: IPOPT's path depends on it)."""
    from ...problem import (
        CollisionAvoidance,
        FramePath,
        JointAccelerationLimits,
        JointBoundary,
        OptProblem,
        Smoothness,
    )

    prob = OptProblem(robot, o.n_intervals, T, n_sub=o.n_sub, transcription="knots")
    zero = np.zeros(robot.nj)
    prob.add_constraint(JointBoundary("start", q=task.q_start, qd=zero, qdd=zero))
    prob.add_constraint(JointBoundary("end", qd=zero))
    for a, h in hands.items():
        fr = robot.arm(a).ee_frame
        prob.add_constraint(FramePath(fr, h.pose, position_only=o.position_only), name=f"path_{a}")
        if o.position_only:
            prob.add_constraint(EndOrientation(fr, h.pose(T).rotation), name=f"goal_orientation_{a}")
            if o.orientation_weight > 0:
                prob.add_cost(FramePath(fr, h.pose), weight=o.orientation_weight, name=f"orientation_{a}")
    _attitude_and_limits(prob, robot, o)
    prob.add_constraint(InteriorVelocityLimits(scale=o.rate_margin))
    prob.add_constraint(JointAccelerationLimits(limit=o.joint_accel_limit))
    prob.add_constraint(CollisionAvoidance(None, margin=o.link_margin, self_collision=True, held_object=False),
                        name="links")
    if task.scene.obstacles:
        prob.add_constraint(CollisionAvoidance(task.scene, margin=o.obstacle_margin, self_collision=False,
                                               held_object=False), name="obstacles")
    prob.add_cost(Smoothness("jerk"))
    return prob
