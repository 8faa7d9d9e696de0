"""Warm starts from planner paths: resample a joint path by arc length and project every sample
back onto the closed-chain manifold.

A planner's path (e.g. TCBiRRT's) is a polyline of configurations that each satisfy the closed-
chain constraint; straight segments between them do not. :func:`manifold_resample` resamples the
polyline uniformly in joint-space arc length and projects each sample with
:func:`project_closed_chain` (Newton–Raphson with the minimum-norm step ``dq = −J_h⁺ h`` over both
arms, the projection CBiRRT2 uses), seeded by the linear interpolate.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .robot import RobotModel
from .splines import resample_path

__all__ = ["closed_chain_residual", "project_closed_chain", "manifold_resample", "ProjectionResult"]


@dataclass(frozen=True)
class ProjectionResult:
    q: np.ndarray
    success: bool
    iterations: int
    residual: float


def closed_chain_residual(robot: RobotModel, q, closed_chain, data: pin.Data | None = None):
    """``(h (6,), J_h (6 × nv))``: relative-pose error ``[p_rel − p*; vee(E − Eᵀ)/2]`` with
    ``E = R*ᵀ R_rel`` (the residual of :class:`~optplan.problem.ClosedChain`), expressed in hand A's
    frame, and its exact Jacobian."""
    data = data or robot.model.createData()
    a, b = robot.arm(closed_chain.arm_a), robot.arm(closed_chain.arm_b)
    model = robot.model
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    Ma, Mb = data.oMf[a.ee_frame_id], data.oMf[b.ee_frame_id]
    rel = Ma.actInv(Mb)
    tgt = closed_chain.relative
    E = tgt.rotation.T @ rel.rotation
    # vee((E − Eᵀ)/2) = sin θ · axis: exact to round-off near E = I (an acos-based log is not)
    h = np.concatenate([rel.translation - tgt.translation,
                        0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])])
    LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    Ja = pin.getFrameJacobian(model, data, a.ee_frame_id, LWA)
    Jb = pin.getFrameJacobian(model, data, b.ee_frame_id, LWA)
    RaT = Ma.rotation.T
    d = Mb.translation - Ma.translation
    skew_d = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
    Jlin = RaT @ (Jb[:3] - Ja[:3] + skew_d @ Ja[3:])
    # Ė = E [ω]× with ω = R_bᵀ (ω_b − ω_a) (body rate), and d vee((E − Eᵀ)/2) = ½ (tr E · I − Eᵀ) ω
    Jang = 0.5 * (np.trace(E) * np.eye(3) - E.T) @ Mb.rotation.T @ (Jb[3:] - Ja[3:])
    return h, np.vstack([Jlin, Jang])


def project_closed_chain(robot: RobotModel, q, closed_chain, *, tol: float = 1e-10, max_iterations: int = 50,
                         data: pin.Data | None = None) -> ProjectionResult:
    """Newton–Raphson projection onto ``T_a⁻¹ T_b = relative`` with minimum-norm steps over the
    two arms' joints (joint limits clipped). ``tol`` on ‖h‖∞ ([m], [rad])."""
    q = np.array(robot.check_q(q), float)
    data = data or robot.model.createData()
    cols = np.concatenate([robot.arm(closed_chain.arm_a).v_idx, robot.arm(closed_chain.arm_b).v_idx])
    qidx = np.concatenate([robot.arm(closed_chain.arm_a).q_idx, robot.arm(closed_chain.arm_b).q_idx])
    lo = np.concatenate([robot.lower[robot.arm(closed_chain.arm_a).j_idx], robot.lower[robot.arm(closed_chain.arm_b).j_idx]])
    hi = np.concatenate([robot.upper[robot.arm(closed_chain.arm_a).j_idx], robot.upper[robot.arm(closed_chain.arm_b).j_idx]])
    res = np.inf
    for it in range(max_iterations + 1):
        h, J = closed_chain_residual(robot, q, closed_chain, data)
        res = float(np.abs(h).max())
        if res < tol:
            return ProjectionResult(q, True, it, res)
        if it == max_iterations:
            break
        Jc = J[:, cols]
        dq = -Jc.T @ np.linalg.solve(Jc @ Jc.T + 1e-12 * np.eye(6), h)
        q[qidx] = np.clip(q[qidx] + dq, lo, hi)
    return ProjectionResult(q, False, max_iterations, res)


def manifold_resample(robot: RobotModel, path, n: int, closed_chain=None) -> tuple[np.ndarray, bool]:
    """``n`` configurations uniform in joint-space arc length along ``path`` (M × nq), each
    projected onto the closed-chain manifold when ``closed_chain`` is given. Returns the array and
    whether every projection converged."""
    path = np.asarray(path, float)
    if path.ndim != 2 or path.shape[1] != robot.nq or path.shape[0] < 2:
        raise ValueError(f"path: expected (M ≥ 2, {robot.nq}) configurations, got shape {path.shape}")
    _, Q = resample_path(path, int(n))
    if closed_chain is None:
        return Q, True
    ok = True
    data = robot.model.createData()
    for i in range(1, len(Q) - 1):
        r = project_closed_chain(robot, Q[i], closed_chain, data=data)
        Q[i] = r.q
        ok &= r.success
    return Q, bool(ok)
