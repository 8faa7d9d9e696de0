"""Where a free-floating robot can hold an object: the zero-momentum world IK.

With zero momentum the system's centre of mass does not move, so the base POSITION follows from the
joints and the base attitude: ``p_base = c0 − R_base · c_b(q)`` (``c_b``: the centre of mass in the
base frame). :func:`zero_momentum_ik` finds joints and a base attitude that put every hand at its
grasp on the object at a world pose with the centre of mass at ``c0`` (Levenberg–Marquardt on
``(q, log R_base)``, finite-difference Jacobian, from several seeds). The base attitude along a path
is path-dependent, so a solution says where the arms CAN hold the object (a reachable world goal,
and the base pose to expect on arrival), not that a given path ends there.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from ..model.robot import RobotModel

if TYPE_CHECKING:
    from .floating_carry import FloatingCarryPlanner
    from .validity import ValidityChecker

__all__ = ["zero_momentum_ik", "nearest_held_attitude", "limited_step", "self_motion_clear"]


def _full(robot: RobotModel, q: np.ndarray, base: pin.SE3) -> np.ndarray:
    return np.concatenate([pin.SE3ToXYZQUAT(base), q])


def zero_momentum_ik(robot: RobotModel, grasps: dict[str, pin.SE3], goal: pin.SE3, seeds: list[np.ndarray],
                     com: np.ndarray, rng: np.random.Generator, *, attitude: pin.SE3 | None = None,
                     n_random: int = 8, spread_rad: float = 0.6, iters: int = 100,
                     tol: float = 1e-10, fix_attitude: bool = False) -> tuple[np.ndarray, pin.SE3, float]:
    """Joints [rad] and base pose holding the object at the world ``goal`` (each arm's hand at
    ``goal · grasps[arm]``) with the centre of mass at ``com`` [m, world]; attitudes are searched
    around ``attitude`` (default identity). Seeds: ``seeds``, then ``n_random`` normal draws
    (``spread_rad`` per joint) around the first. Returns ``(q, base, residual)`` of the best solution
    found (residual = norm of the hands' log-SE(3) errors [m, rad]; ≤ ``tol`` when it converged).
    With ``fix_attitude`` the base attitude is held at ``attitude`` and only the joints are solved
    (the arms' redundancy absorbs it): the solution is where the arms hold the object for THAT
    arrival attitude, not for one the search drifted to."""
    m, d = robot.model, robot.model.createData()
    R0 = np.eye(3) if attitude is None else attitude.rotation
    targets = [goal * grasps[a] for a in grasps]
    fids = [robot.arm(a).ee_frame_id for a in grasps]
    nj, ident = robot.nj, pin.SE3.Identity()

    def state(x: np.ndarray) -> tuple[np.ndarray, pin.SE3]:
        q = np.clip(x[:nj], robot.lower, robot.upper)
        R = R0 @ pin.exp3(x[nj:])
        cb = pin.centerOfMass(m, d, _full(robot, q, ident))
        return q, pin.SE3(R, np.asarray(com, float) - R @ cb)

    def residual(x: np.ndarray) -> np.ndarray:
        q, base = state(x)
        pin.framesForwardKinematics(m, d, _full(robot, q, base))
        return np.concatenate([pin.log6(T.actInv(d.oMf[f])).vector for T, f in zip(targets, fids)])

    best: tuple[float, np.ndarray] = (math.inf, np.r_[seeds[0], np.zeros(3)])
    starts = list(seeds) + [seeds[0] + rng.normal(0.0, spread_rad, nj) for _ in range(n_random)]
    h = 1e-7
    for s in starts:
        x = np.r_[np.clip(s, robot.lower, robot.upper), np.zeros(3)]
        r = residual(x)
        e, lam = float(np.linalg.norm(r)), 1e-3
        for _ in range(iters):
            if e <= tol:
                break
            nx = nj if fix_attitude else len(x)
            J = np.zeros((len(r), len(x)))
            for k in range(nx):
                xk = x.copy()
                xk[k] += h
                J[:, k] = (residual(xk) - r) / h
            xt = x - np.linalg.solve(J.T @ J + lam * np.eye(len(x)), J.T @ r)
            rt = residual(xt)
            et = float(np.linalg.norm(rt))
            if et < e:
                x, r, e, lam = xt, rt, et, max(lam * 0.3, 1e-12)
            else:
                lam *= 10.0
                if lam > 1e4:
                    break
        if e < best[0]:
            best = (e, x)
        if e <= tol:
            break
    q, base = state(best[1])
    return q, base, best[0]


def nearest_held_attitude(robot: RobotModel, grasps: dict[str, pin.SE3], goal: pin.SE3, seeds: list[np.ndarray],
                          com: np.ndarray, rng: np.random.Generator, attitude: pin.SE3, *, steps: int = 8,
                          margin_steps: int = 1, tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray] | None:
    """A base attitude near ``attitude`` (3×3 world rotation) at which the arms hold the object at the
    world ``goal`` with the centre of mass at ``com``, and the joints [rad] doing it, or None.

    A free :func:`zero_momentum_ik` from ``attitude`` may land far from it (the search moves the
    attitude as freely as the joints); this walks the geodesic from ``attitude`` to that free
    solution's attitude in ``steps`` equal steps, holding the attitude at each
    (``fix_attitude``), and returns the first attitude ``margin_steps`` steps past the first one
    that holds the goal (a margin: the motion that lands the goal turns the base too)."""
    q_f, b_f, res = zero_momentum_ik(robot, grasps, goal, seeds, com, rng, attitude=attitude, n_random=4)
    if res > tol:
        return None
    w = np.asarray(pin.log3(attitude.rotation.T @ b_f.rotation))
    seeds = list(seeds) + [q_f]
    first = None
    for i in range(1, steps + 1):
        R = attitude.rotation @ pin.exp3((i / steps) * w)
        q, _, r = zero_momentum_ik(robot, grasps, goal, seeds, com, rng, attitude=pin.SE3(R, np.zeros(3)),
                                   n_random=0, fix_attitude=True)
        if r <= tol:
            if first is None:
                first = i
            if i >= min(steps, first + margin_steps):
                return R, q
            seeds = [q] + seeds
    return None


def limited_step(J: np.ndarray, e: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                 max_step: float, damping: float = 1e-6, centring: float = 0.1) -> np.ndarray:
    """A joint step ``dq`` [rad] with ``J dq ≈ e`` that keeps ``q + dq`` within ``[lower, upper]``:
    damped least squares (``damping``) on the free joints; a joint whose step would cross its limit
    is moved to the limit and held there while the others are re-solved (active set, at most one
    pass per joint); the redundancy left pulls the free joints toward the middle of their range
    (null-space term, ``centring`` × the offset per step); scaled so that no joint moves more than
    ``max_step`` [rad]. A plain Newton step clipped at a limit is another, inconsistent step: near a
    limit it drives the arm into the singularity the limit makes."""
    n = len(q)
    free = np.ones(n, bool)
    fixed = np.zeros(n)
    mid = 0.5 * (lower + upper)
    dq = np.zeros(n)
    for _ in range(n):
        if not free.any():
            break
        Jf = J[:, free]
        A = Jf @ Jf.T + damping * np.eye(len(e))
        pull = centring * (mid[free] - q[free])
        step_f = Jf.T @ np.linalg.solve(A, e - J @ fixed) + pull - Jf.T @ np.linalg.solve(A, Jf @ pull)
        dq = fixed.copy()
        dq[free] = step_f
        dq *= min(1.0, max_step / max(float(np.max(np.abs(dq))), 1e-12))
        over = free & ((q + dq > upper) | (q + dq < lower))
        if not over.any():
            return dq
        fixed[over] = np.clip(q + dq, lower, upper)[over] - q[over]
        free &= ~over
    return np.clip(q + dq, lower, upper) - q


def self_motion_clear(carry: FloatingCarryPlanner, validity: ValidityChecker, q: np.ndarray, object_in_base: pin.SE3, base: pin.SE3,
                      rng: np.random.Generator, *, directions: int = 8, steps: int = 16,
                      step_rad: float = 0.12) -> np.ndarray | None:
    """Joints on the SAME self-motion component as ``q`` (both hands holding the object still at
    ``object_in_base``, base at ``base``) that are collision-free, or None: walks from ``q`` along
    the arms' redundancy (per arm the null space of its hand Jacobian, a random mix of the arms per
    walk; ``directions`` walks of ``steps`` steps of ≤ ``step_rad`` [rad]), each step re-closed on
    the chain by :meth:`~optplan.planners.floating_carry.FloatingCarryPlanner.hold` seeded with the
    step (so it stays on the branch). The walk itself is not checked: the planner's trees connect
    to the result like to any root."""
    robot = carry.robot
    m, d = robot.model, robot.model.createData()
    for _ in range(directions):
        mix = rng.normal(size=len(carry.arm_names))
        qk = np.array(q, float)
        prev: dict[str, np.ndarray] = {}
        for _ in range(steps):
            full = carry._full(qk)
            pin.computeJointJacobians(m, d, full)
            pin.framesForwardKinematics(m, d, full)
            dq = np.zeros(robot.nj)
            for w, a in zip(mix, carry.arm_names):
                arm = robot.arm(a)
                J = pin.getFrameJacobian(m, d, arm.ee_frame_id, pin.LOCAL)[:, arm.v_idx]
                n = np.linalg.svd(J)[2][-1]
                if a in prev and float(n @ prev[a]) < 0.0:   # the SVD's sign is arbitrary: keep walking one way
                    n = -n
                prev[a] = n
                dq[arm.j_idx] += w * n
            dq *= step_rad / max(float(np.max(np.abs(dq))), 1e-12)
            qn = carry.hold(np.clip(qk + dq, robot.lower, robot.upper), object_in_base)
            if qn is None or float(np.max(np.abs(qn - qk))) > 2.0 * step_rad:
                break
            qk = qn
            if validity.is_valid(carry._full(qk, base)):
                return qk
    return None
