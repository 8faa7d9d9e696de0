"""Inverse kinematics: damped least squares on one arm or several at once (the two-hand IK of an
object pose, :func:`optplan.constraints.closed_chain.solve_grasp_ik`, calls it).

Errors follow the TCBiRRT paper Eq. 5-6: position error ``e_p = p_goal − p`` [m] and orientation error
``e_o = R_goal φ(Rᵀ R_goal)`` (exponential coordinates, world axes) [rad].
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import OptionError
from ..geometry.spatial import check_pose
from .robot import RobotModel

__all__ = ["IKOptions", "IKResult", "solve_arm_ik", "solve_multi", "pose_error"]
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class IKOptions:
    """Damped least-squares IK options."""

    #: Convergence threshold on the position error, ε_p of the TCBiRRT paper [m].
    tol_position: float = 1e-6
    #: Convergence threshold on the orientation error, ε_o [rad].
    tol_orientation: float = 1e-6
    #: Iteration cap [count].
    max_iterations: int = 200
    #: λ of the damped least squares ``Jᵀ (J Jᵀ + λ² I)⁻¹`` [-].
    damping: float = 1e-3
    #: Largest joint step per iteration [rad] (the step is clipped).
    max_step: float = 0.3
    #: Clip into the joint limits at every iteration.
    respect_limits: bool = True

    def __post_init__(self):
        for name in ("tol_position", "tol_orientation", "damping", "max_step"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not (np.isfinite(v) and v > 0):
                raise OptionError(f"IKOptions.{name}: expected a positive number, got {v!r}")
        m = self.max_iterations
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
            raise OptionError(f"IKOptions.max_iterations: expected an integer ≥ 1, got {m!r}")


@dataclass(frozen=True)
class IKResult:
    """``success``, the full configuration ``q``, iterations, final errors [m], [rad];
    ``status``: ``"converged"``, ``"not_converged"``, or ``"in_collision"`` (converged, but
    closer than the clearance asked for; :func:`~optplan.constraints.closed_chain.solve_grasp_ik`
    with a checker); ``clearance`` [m]: the exact clearance of ``q`` when checked (else NaN)."""

    success: bool
    q: np.ndarray
    iterations: int
    position_error: float
    orientation_error: float
    status: str = ""
    clearance: float = float("nan")

    def __post_init__(self) -> None:
        if not self.status:
            object.__setattr__(self, "status", "converged" if self.success else "not_converged")


def pose_error(M: pin.SE3, goal: pin.SE3) -> np.ndarray:
    """``[e_p; e_o]`` (world axes) from the current placement M to the goal (the TCBiRRT paper Eq. 5-6)."""
    ep = goal.translation - M.translation
    eo = M.rotation @ pin.log3(M.rotation.T @ goal.rotation)
    return np.concatenate([ep, eo])


def solve_multi(robot: RobotModel, data: pin.Data, q0: np.ndarray, targets, opts: IKOptions) -> IKResult:
    """Damped least squares on several ``(arm, goal)`` pairs at once from ``q0``; only those arms'
    joints move (``data``: a Pinocchio data of the robot's model)."""
    q = robot.check_q(q0, "q0").copy()
    model = robot.model
    arms = [robot.arm(a) for a, _ in targets]
    goals = [g for _, g in targets]
    lo, hi = robot.lower, robot.upper
    ep = eo = np.inf
    for it in range(1, opts.max_iterations + 1):
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        errs, ep, eo = [], 0.0, 0.0
        for a, g in zip(arms, goals):
            e = pose_error(data.oMf[a.ee_frame_id], g)
            ep, eo = max(ep, float(np.linalg.norm(e[:3]))), max(eo, float(np.linalg.norm(e[3:])))
            errs.append(e)
        if ep < opts.tol_position and eo < opts.tol_orientation:
            return IKResult(True, q, it - 1, ep, eo)
        for a, e in zip(arms, errs):
            J = pin.getFrameJacobian(model, data, a.ee_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:, a.v_idx]
            dq = J.T @ np.linalg.solve(J @ J.T + opts.damping ** 2 * np.eye(6), e)
            m = np.abs(dq).max()
            if m > opts.max_step:
                dq *= opts.max_step / m
            qa = q[a.q_idx] + dq
            if opts.respect_limits:
                qa = np.clip(qa, lo[a.j_idx], hi[a.j_idx])
            q[a.q_idx] = qa
    pin.framesForwardKinematics(model, data, q)
    ep = max(float(np.linalg.norm(pose_error(data.oMf[a.ee_frame_id], g)[:3])) for a, g in zip(arms, goals))
    eo = max(float(np.linalg.norm(pose_error(data.oMf[a.ee_frame_id], g)[3:])) for a, g in zip(arms, goals))
    ok = ep < opts.tol_position and eo < opts.tol_orientation
    return IKResult(bool(ok), q, opts.max_iterations, float(ep), float(eo))


def solve_arm_ik(robot: RobotModel, arm: str, goal: pin.SE3, q0, options: IKOptions | None = None,
                 data: pin.Data | None = None) -> IKResult:
    """Move ``arm``'s joints from ``q0`` until its end-effector reaches ``goal`` (world)."""
    check_pose(goal, "solve_arm_ik: goal")
    return solve_multi(robot, data or robot.model.createData(), q0, [(arm, goal)], options or IKOptions())


def __getattr__(name):
    if name == "solve_grasp_ik":
        from .._compat import moved

        return moved(__name__, name, "optplan.constraints.closed_chain")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
