"""The term library of :class:`OptProblem`.

A term is a residual ``r`` (a vector of CasADi expressions of the transcription) with bounds
``lower ≤ r ≤ upper``. Added with ``add_constraint`` the bounds are enforced; added with
``add_cost`` the cost is ``weight · Σ (r − clip(r, lower, upper))²`` — the squared bound violation
(for equality terms, ``Σ (r − target)²``) — unless the term defines its own cost (smoothness, path
length, duration). Every term also evaluates the same residual **numerically with Pinocchio**
(``numeric``), independent of the CasADi expressions; the tests compare the two over a registry.

Pose residuals avoid Euler angles: position error plus ``vee(E − Eᵀ)/2`` of the rotation error
``E = R_targetᵀ R`` (= sin θ · axis), together with ``trace(E) ≥ 1`` (θ ≤ 90°) so that the spurious
θ = 180° zero is excluded.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import casadi as ca
import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError
from ..robot import RobotModel
from .transcription import Transcription

__all__ = [
    "Term", "JointBoundary", "JointPositionLimits", "JointVelocityLimits", "JointAccelerationLimits",
    "FramePose", "FramePath", "ClosedChain", "OrientationConstraint", "BaseAttitude", "Smoothness",
    "PathLength", "Duration", "NumericTrajectory", "pose_residual", "pose_residual_numeric",
]


# --------------------------------------------------------------------------- helpers
def _vee_skew(E):
    return 0.5 * ca.vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1])


def pose_residual(R, p, R_target, p_target):
    """``[p − p_t (3); vee(E − Eᵀ)/2 (3)]`` and ``trace(E)`` with ``E = R_tᵀ R`` (CasADi)."""
    E = ca.DM(R_target).T @ R if isinstance(R_target, np.ndarray) else R_target.T @ R
    return ca.vertcat(p - p_target, _vee_skew(E)), ca.trace(E)


def pose_residual_numeric(M: pin.SE3, target: pin.SE3) -> tuple[np.ndarray, float]:
    E = target.rotation.T @ M.rotation
    s = 0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])
    return np.concatenate([M.translation - target.translation, s]), float(np.trace(E))


@dataclass
class NumericTrajectory:
    """Knot values for numeric term evaluation: ``q`` (N+1, nj), ``qd``, ``qdd``, ``jerk`` (N, nj),
    ``T`` [s], ``base_quat`` (N+1, 4) for floating robots (base position from the fixed CoM)."""

    robot: RobotModel
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    jerk: np.ndarray
    T: float
    base_quat: np.ndarray | None = None
    com0: np.ndarray | None = None
    _data: pin.Data | None = field(default=None, repr=False)
    #: knots pinned by a JointBoundary (k -> q), as ``Transcription.pinned_q``
    pinned_q: dict = field(default_factory=dict)

    @property
    def N(self) -> int:
        return self.q.shape[0] - 1

    @property
    def h(self) -> float:
        return self.T / self.N

    def q_full(self, k: int) -> np.ndarray:
        r = self.robot
        if not r.is_floating:
            return self.q[k]
        quat = self.base_quat[k] / np.linalg.norm(self.base_quat[k])
        qf = np.concatenate([np.zeros(3), quat, self.q[k]])
        data = self.data
        c_b = pin.centerOfMass(r.model, data, np.concatenate([np.zeros(3), [0, 0, 0, 1.0], self.q[k]]))
        R = pin.Quaternion(quat[3], quat[0], quat[1], quat[2]).toRotationMatrix()
        qf[:3] = (self.com0 if self.com0 is not None else np.zeros(3)) - R @ c_b
        return qf

    @property
    def data(self) -> pin.Data:
        if self._data is None:
            self._data = self.robot.model.createData()
        return self._data

    def frame(self, frame, k) -> pin.SE3:
        """Frame placement at knot k (int) or interior point (interval, fraction) (fixed base)."""
        fid = self.robot.frame_id(frame)
        if isinstance(k, tuple):
            i, f = k
            tau = f * self.h
            q = self.q[i] + tau * self.qd[i] + tau**2 / 2 * self.qdd[i] + tau**3 / 6 * self.jerk[i]
        else:
            q = self.q_full(k)
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        return self.data.oMf[fid].copy()


def _knots(at, N: int) -> list[int]:
    if at == "all":
        return list(range(N + 1))
    if at == "start":
        return [0]
    if at == "end":
        return [N]
    if isinstance(at, (int, np.integer)):
        if not -N - 1 <= int(at) <= N:
            raise ConfigurationError(f"knot index {at} out of range for N = {N} intervals")
        return [int(at) % (N + 1)]
    out = []
    for a in at:
        if not -N - 1 <= int(a) <= N:
            raise ConfigurationError(f"knot index {a} in {list(at)} out of range for N = {N} intervals")
        out.append(int(a) % (N + 1))
    return out


# --------------------------------------------------------------------------- base class
class Term:
    """Base class: subclasses implement ``residual(tp) -> (expr, lower, upper)`` and
    ``numeric(traj) -> ndarray`` (same quantity, Pinocchio); optional ``cost(tp)``."""

    default_name = "term"
    cost_only = False
    constraint_only = False

    def residual(self, tp: Transcription):
        raise TypeError(f"{type(self).__name__} is a cost-only term: it has no residual/constraint form")

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        raise TypeError(f"{type(self).__name__} is a cost-only term: it has no residual form")

    def cost(self, tp: Transcription):
        r, lo, hi = self.residual(tp)
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        viol = []
        for i in range(r.shape[0]):
            if lo[i] == hi[i]:
                viol.append(r[i] - lo[i])
            else:
                if np.isfinite(hi[i]):
                    viol.append(ca.fmax(r[i] - hi[i], 0))
                if np.isfinite(lo[i]):
                    viol.append(ca.fmin(r[i] - lo[i], 0))
        v = ca.vertcat(*viol)
        return ca.sumsqr(v)

    def cost_numeric(self, traj: NumericTrajectory) -> float:
        """Numeric value of :meth:`cost` (default: squared bound violation of ``numeric``)."""
        r = self.numeric(traj)
        lo, hi = self._bounds_numeric(traj)
        return float(np.sum(np.where(lo == hi, r - lo, np.maximum(r - hi, 0) + np.minimum(r - lo, 0)) ** 2))

    def _bounds_numeric(self, traj):
        raise TypeError(f"{type(self).__name__} is a cost-only term: it has no bounds")


# --------------------------------------------------------------------------- joint terms
@dataclass
class JointBoundary(Term):
    """Joint values at the start or end knot: any of ``q`` [rad], ``qd`` [rad/s], ``qdd`` [rad/s²]."""

    at: str = "start"
    q: Sequence[float] | None = None
    qd: Sequence[float] | None = None
    qdd: Sequence[float] | None = None
    default_name = "boundary"

    def _parts(self, N):
        if self.at not in ("start", "end"):
            raise ValueError(f"JointBoundary.at: expected 'start' or 'end', got {self.at!r}")
        k = 0 if self.at == "start" else N
        return k, [(n, v) for n, v in (("q", self.q), ("qd", self.qd), ("qdd", self.qdd)) if v is not None]

    def residual(self, tp):
        k, parts = self._parts(tp.N)
        if not parts:
            raise ValueError("JointBoundary: give at least one of q, qd, qdd")
        exprs, targets = [], []
        for n, v in parts:
            v = tp.robot.check_joints(v, f"JointBoundary.{n}")
            exprs.append({"q": tp.q, "qd": tp.qd, "qdd": tp.qdd}[n](k))
            targets.append(v)
        t = np.concatenate(targets)
        return ca.vertcat(*exprs), t, t

    def numeric(self, traj):
        k, parts = self._parts(traj.N)
        return np.concatenate([getattr(traj, n)[k] for n, _ in parts])

    def _bounds_numeric(self, traj):
        k, parts = self._parts(traj.N)
        t = np.concatenate([np.asarray(v, float) for _, v in parts])
        return t, t


@dataclass
class _JointBox(Term):
    lower: Sequence[float] | None = None
    upper: Sequence[float] | None = None
    which = "q"

    def _lims(self, robot):  # overridden by each concrete limit term
        raise TypeError(f"{type(self).__name__} is abstract: use JointPositionLimits, "
                        "JointVelocityLimits or JointAccelerationLimits")

    def residual(self, tp):
        lo, hi = self._lims(tp.robot)
        get = {"q": tp.q, "qd": tp.qd, "qdd": tp.qdd}[self.which]
        ks = range(tp.N + 1)
        return ca.vertcat(*[get(k) for k in ks]), np.tile(lo, len(ks)), np.tile(hi, len(ks))

    def bounds_on(self, tp):
        """As a constraint this term is a plain bound on knot variables: (indices into x, lower,
        upper). IPOPT treats variable bounds much more cheaply than general constraints."""
        lo, hi = self._lims(tp.robot)
        nj, N = tp.nj, tp.N
        block = {"q": 0, "qd": 1, "qdd": 2}[self.which]
        idx = block * nj * (N + 1) + np.arange(nj * (N + 1))
        sc = tp.variable_scale(self.which)  # the variables are scaled (transcription docstring)
        return idx, sc * np.tile(lo, N + 1), sc * np.tile(hi, N + 1)

    def numeric(self, traj):
        return getattr(traj, self.which).reshape(-1)

    def _bounds_numeric(self, traj):
        lo, hi = self._lims(traj.robot)
        return np.tile(lo, traj.N + 1), np.tile(hi, traj.N + 1)


@dataclass
class JointPositionLimits(_JointBox):
    """``lower ≤ q_k ≤ upper`` at every knot [rad] (default: the robot's limits)."""

    default_name = "joint_limits"
    which = "q"

    def _lims(self, robot):
        lo = robot.lower if self.lower is None else robot.check_joints(self.lower, "lower")
        hi = robot.upper if self.upper is None else robot.check_joints(self.upper, "upper")
        return lo, hi


@dataclass
class JointVelocityLimits(_JointBox):
    """``|q̇_k| ≤ limit`` [rad/s] (default: the robot's velocity limits); ``lower``/``upper``
    override."""

    limit: Sequence[float] | float | None = None
    default_name = "velocity_limits"
    which = "qd"

    def _lims(self, robot):
        lim = robot.velocity_limit if self.limit is None else np.broadcast_to(
            np.asarray(self.limit, float), (robot.nj,))
        return -lim, lim


@dataclass
class JointAccelerationLimits(_JointBox):
    """``|q̈_k| ≤ limit`` [rad/s²] at every knot (q̈ is piecewise linear, so knots bound it)."""

    limit: Sequence[float] | float = 1.0
    default_name = "acceleration_limits"
    which = "qdd"

    def _lims(self, robot):
        lim = np.broadcast_to(np.asarray(self.limit, float), (robot.nj,))
        return -lim, lim


# --------------------------------------------------------------------------- frame terms
@dataclass
class FramePose(Term):
    """A frame's world pose at a knot (``at``: "start", "end", an index or a list)."""

    frame: str = ""
    target: pin.SE3 | None = None
    at: object = "end"
    position_only: bool = False
    default_name = "frame_pose"

    def residual(self, tp):
        if self.target is None:
            raise ValueError("FramePose.target: expected a pinocchio.SE3")
        rs, lo, hi = [], [], []
        for k in _knots(self.at, tp.N):
            R, p = tp.frame(self.frame, k)
            r, tr = pose_residual(R, p, np.array(self.target.rotation), ca.DM(self.target.translation))
            if self.position_only:
                rs.append(r[:3]); lo += [0.0] * 3; hi += [0.0] * 3
            else:
                rs += [r, tr]; lo += [0.0] * 6 + [1.0]; hi += [0.0] * 6 + [np.inf]
        return ca.vertcat(*rs), np.array(lo), np.array(hi)

    def numeric(self, traj):
        out = []
        for k in _knots(self.at, traj.N):
            r, tr = pose_residual_numeric(traj.frame(self.frame, k), self.target)
            out.append(r[:3] if self.position_only else np.r_[r, tr])
        return np.concatenate(out)

    def _bounds_numeric(self, traj):
        n = len(_knots(self.at, traj.N))
        one = (np.zeros(3), np.zeros(3)) if self.position_only else (np.r_[np.zeros(6), 1.0], np.r_[np.zeros(6), np.inf])
        return np.tile(one[0], n), np.tile(one[1], n)

    def cost(self, tp):
        r, _, _ = self.residual(tp)
        step = 3 if self.position_only else 7
        keep = [i for i in range(r.shape[0]) if self.position_only or i % step != 6]
        return ca.sumsqr(r[keep])

    def cost_numeric(self, traj):
        r = self.numeric(traj)
        step = 3 if self.position_only else 7
        keep = [i for i in range(r.size) if self.position_only or i % step != 6]
        return float(np.sum(r[keep] ** 2))


@dataclass
class FramePath(Term):
    """A frame follows given poses at every knot (``poses``: N+1 SE3, or a callable of time [s])."""

    frame: str = ""
    poses: object = None
    position_only: bool = False
    default_name = "frame_path"

    def _targets(self, N, T):
        if callable(self.poses):
            return [self.poses(T * k / N) for k in range(N + 1)]
        if self.poses is None or len(self.poses) != N + 1:
            raise ValueError(f"FramePath.poses: expected {N + 1} poses (one per knot) or a callable of time")
        return list(self.poses)

    def _T(self, tp):
        if tp.free_time and callable(self.poses):
            raise ValueError("FramePath with a callable of time needs a fixed duration")
        return float(ca.evalf(tp.T)) if not tp.free_time else 1.0

    def residual(self, tp):
        rs, lo, hi = [], [], []
        for k, M in enumerate(self._targets(tp.N, self._T(tp))):
            R, p = tp.frame(self.frame, k)
            r, _ = pose_residual(R, p, np.array(M.rotation), ca.DM(M.translation))
            r = r[:3] if self.position_only else r
            rs.append(r)
        n = sum(x.shape[0] for x in rs)
        return ca.vertcat(*rs), np.zeros(n), np.zeros(n)

    def numeric(self, traj):
        out = []
        for k, M in enumerate(self._targets(traj.N, traj.T)):
            r, _ = pose_residual_numeric(traj.frame(self.frame, k), M)
            out.append(r[:3] if self.position_only else r)
        return np.concatenate(out)

    def _bounds_numeric(self, traj):
        n = (traj.N + 1) * (3 if self.position_only else 6)
        return np.zeros(n), np.zeros(n)


@dataclass
class ClosedChain(Term):
    """Two end-effectors keep their relative pose ``T_a⁻¹ T_b = relative`` at every knot (seed 000
    Eq. 1-2, with the singularity-free residual of the module docstring).

    Knots whose joints a :class:`JointBoundary` pins (``q`` given) and which satisfy the closed
    chain there (≤ ``pinned_tol``) are left out: the rows would repeat the boundary constraint,
    make the constraint Jacobian rank-deficient and IPOPT's multipliers non-unique (measured on
    the transport pipeline: wrong KKT inertia at every iteration, MUMPS pivot tolerance raised to
    0.1 and 2-3× slower factorizations). A pinned configuration that violates it keeps its rows,
    so an inconsistent problem still ends infeasible. The relative pose does not depend on the
    base, so a floating robot's hands are taken in the base frame (cheaper derivatives)."""

    arm_a: str = "A"
    arm_b: str = "B"
    relative: pin.SE3 | None = None
    interior: int = 0  # extra collocation points per interval (fixed-base robots), e.g. 1 = midpoints
    pinned_tol: float = 1e-9
    default_name = "closed_chain"

    def _points(self, N: int, robot: RobotModel | None = None, pinned: dict | None = None) -> list:
        skip = set()
        if pinned and robot is not None and self.relative is not None:
            for k, qk in pinned.items():
                M = self._relative_numeric(robot, robot.configuration(qk) if robot.is_floating else qk)
                r, tr = pose_residual_numeric(M, self.relative)
                if np.abs(r).max() <= self.pinned_tol and tr >= 1.0:
                    skip.add(int(k))
        pts = []
        for k in range(N + 1):
            if k not in skip:
                pts.append(k)
            if k < N:
                pts += [(k, (i + 1) / (self.interior + 1)) for i in range(self.interior)]
        return pts

    def _relative_numeric(self, robot: RobotModel, q) -> pin.SE3:
        fa, fb = self._frames(robot)
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, np.asarray(q, float))
        return data.oMf[robot.frame_id(fa)].actInv(data.oMf[robot.frame_id(fb)])

    @classmethod
    def from_configuration(cls, robot: RobotModel, q, arm_a: str = "A", arm_b: str = "B") -> "ClosedChain":
        """The relative pose the two hands have at the full configuration ``q``."""
        from ..kinematics import Kinematics

        kin = Kinematics(robot)
        Ma, Mb = kin.frame_placements(q, [robot.arm(arm_a).ee_frame, robot.arm(arm_b).ee_frame])
        return cls(arm_a, arm_b, Ma.actInv(Mb))

    @classmethod
    def from_grasps(cls, grasp_a: pin.SE3, grasp_b: pin.SE3, arm_a: str = "A", arm_b: str = "B") -> "ClosedChain":
        """Both hands on one rigid object with grasp frames ``grasp_a``, ``grasp_b`` (object frame)."""
        return cls(arm_a, arm_b, grasp_a.actInv(grasp_b))

    def _frames(self, robot):
        return robot.arm(self.arm_a).ee_frame, robot.arm(self.arm_b).ee_frame

    def residual_at(self, tp, k):
        fa, fb = self._frames(tp.robot)
        Ra, pa = tp.frame(fa, k, base_frame=True)
        Rb, pb = tp.frame(fb, k, base_frame=True)
        Rrel, prel = Ra.T @ Rb, Ra.T @ (pb - pa)
        return pose_residual(Rrel, prel, np.array(self.relative.rotation), ca.DM(self.relative.translation))

    def residual(self, tp):
        if self.relative is None:
            raise ValueError("ClosedChain.relative: expected a pinocchio.SE3 (use from_configuration/from_grasps)")
        rs = []
        pts = self._points(tp.N, tp.robot, tp.pinned_q)
        for k in pts:
            r, tr = self.residual_at(tp, k)
            rs += [r, tr]
        lo = np.tile(np.r_[np.zeros(6), 1.0], len(pts))
        hi = np.tile(np.r_[np.zeros(6), np.inf], len(pts))
        return ca.vertcat(*rs), lo, hi

    def numeric(self, traj):
        fa, fb = self._frames(traj.robot)
        out = []
        for k in self._points(traj.N, traj.robot, traj.pinned_q):
            Ma, Mb = traj.frame(fa, k), traj.frame(fb, k)
            r, tr = pose_residual_numeric(Ma.actInv(Mb), self.relative)
            out.append(np.r_[r, tr])
        return np.concatenate(out) if out else np.zeros(0)

    def _bounds_numeric(self, traj):
        n = len(self._points(traj.N, traj.robot, traj.pinned_q))
        return (np.tile(np.r_[np.zeros(6), 1.0], n), np.tile(np.r_[np.zeros(6), np.inf], n))


@dataclass
class OrientationConstraint(Term):
    """A body axis stays within ``max_angle`` [rad] of a world direction at every knot (seed 002's
    orientation constraint, e.g. a cup kept upright): ``(R a_local) · a_world ≥ cos(max_angle)``."""

    frame: str = ""
    axis_local: Sequence[float] = (0.0, 0.0, 1.0)
    axis_world: Sequence[float] = (0.0, 0.0, 1.0)
    max_angle: float = 0.1
    default_name = "orientation"

    def _axes(self):
        a = np.asarray(self.axis_local, float)
        b = np.asarray(self.axis_world, float)
        return a / np.linalg.norm(a), b / np.linalg.norm(b)

    def residual(self, tp):
        a, b = self._axes()
        r = ca.vertcat(*[ca.dot(tp.frame(self.frame, k)[0] @ ca.DM(a), ca.DM(b)) for k in range(tp.N + 1)])
        return r, np.full(tp.N + 1, np.cos(self.max_angle)), np.full(tp.N + 1, np.inf)

    def numeric(self, traj):
        a, b = self._axes()
        return np.array([traj.frame(self.frame, k).rotation @ a @ b for k in range(traj.N + 1)])

    def _bounds_numeric(self, traj):
        return np.full(traj.N + 1, np.cos(self.max_angle)), np.full(traj.N + 1, np.inf)


@dataclass
class BaseAttitude(Term):
    """Base orientation of a free-floating robot at a knot equals ``target`` (a rotation matrix;
    default identity): residual ``vee(E − Eᵀ)/2`` and ``trace(E) ≥ 1`` with ``E = R_tᵀ R_b`` —
    attitude restoration when ``target`` is the initial attitude and ``at="end"``."""

    target: np.ndarray | None = None
    at: object = "end"
    default_name = "base_attitude"

    def _target(self):
        return np.eye(3) if self.target is None else np.asarray(self.target, float)

    def residual(self, tp):
        if not tp.floating:
            raise ConfigurationError("BaseAttitude needs a free-floating robot")
        rs = []
        for k in _knots(self.at, tp.N):
            E = ca.DM(self._target()).T @ tp.base_rotation(k)
            rs += [_vee_skew(E), ca.trace(E)]
        n = len(_knots(self.at, tp.N))
        return ca.vertcat(*rs), np.tile(np.r_[0, 0, 0, 1.0], n), np.tile(np.r_[0, 0, 0, np.inf], n)

    def numeric(self, traj):
        out = []
        for k in _knots(self.at, traj.N):
            x, y, z, w = traj.base_quat[k] / np.linalg.norm(traj.base_quat[k])
            E = self._target().T @ pin.Quaternion(w, x, y, z).toRotationMatrix()
            out.append(np.r_[0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]]), np.trace(E)])
        return np.concatenate(out)

    def _bounds_numeric(self, traj):
        n = len(_knots(self.at, traj.N))
        return np.tile(np.r_[0, 0, 0, 1.0], n), np.tile(np.r_[0, 0, 0, np.inf], n)

    def cost(self, tp):
        r, _, _ = self.residual(tp)
        return ca.sumsqr(r[[i for i in range(r.shape[0]) if i % 4 != 3]])

    def cost_numeric(self, traj):
        r = self.numeric(traj)
        return float(np.sum(r[[i for i in range(r.size) if i % 4 != 3]] ** 2))


# --------------------------------------------------------------------------- cost-only terms
@dataclass
class Smoothness(Term):
    """Integral of a squared derivative: ``"jerk"`` (∫‖j‖² dt = h Σ‖j_k‖², exact),
    ``"acceleration"`` (∫‖q̈‖² dt, exact for the piecewise-linear q̈) or ``"velocity"``
    (∫‖q̇‖² dt, exact for the piecewise-quadratic q̇)."""

    order: str = "jerk"
    default_name = "smoothness"
    cost_only = True

    def _check(self):
        if self.order not in ("jerk", "acceleration", "velocity"):
            raise ValueError(f"Smoothness.order: expected 'jerk', 'acceleration' or 'velocity', got {self.order!r}")

    def cost(self, tp):
        self._check()
        h, N = tp.h, tp.N
        if self.order == "jerk":
            return h * ca.sumsqr(tp.J)
        if self.order == "acceleration":
            A = tp.A
            return h / 3 * sum(ca.sumsqr(A[:, k]) + ca.dot(A[:, k], A[:, k + 1]) + ca.sumsqr(A[:, k + 1])
                               for k in range(N))
        V, A, J = tp.V, tp.A, tp.J
        tot = 0
        for k in range(N):  # exact ∫‖v + a τ + j τ²/2‖² dτ over [0, h]
            v, a, j = V[:, k], A[:, k], J[:, k]
            tot = tot + (h * ca.sumsqr(v) + h**2 * ca.dot(v, a) + h**3 / 3 * (ca.sumsqr(a) + ca.dot(v, j))
                         + h**4 / 4 * ca.dot(a, j) + h**5 / 20 * ca.sumsqr(j))
        return tot

    def cost_numeric(self, traj):
        self._check()
        from scipy.integrate import quad_vec

        N, h = traj.N, traj.h

        def integrand(t):
            k = min(int(t / h), N - 1)
            tau = t - k * h
            q0, v0, a0, j0 = traj.q[k], traj.qd[k], traj.qdd[k], traj.jerk[k]
            val = {"jerk": j0, "acceleration": a0 + tau * j0, "velocity": v0 + tau * a0 + tau**2 / 2 * j0}[self.order]
            return float(val @ val)

        return float(sum(quad_vec(integrand, k * h, (k + 1) * h)[0] for k in range(N)))


@dataclass
class PathLength(Term):
    """Joint-space path length ``Σ_k sqrt(‖q_{k+1} − q_k‖² + ε²) − ε`` [rad] (smoothed at 0)."""

    eps: float = 1e-6
    default_name = "path_length"
    cost_only = True

    def cost(self, tp):
        return sum(ca.sqrt(ca.sumsqr(tp.Q[:, k + 1] - tp.Q[:, k]) + self.eps**2) - self.eps for k in range(tp.N))

    def cost_numeric(self, traj):
        d = np.diff(traj.q, axis=0)
        return float(np.sum(np.sqrt(np.sum(d**2, axis=1) + self.eps**2) - self.eps))


@dataclass
class Duration(Term):
    """Total duration ``T`` [s] (a cost for free-final-time problems)."""

    default_name = "duration"
    cost_only = True

    def cost(self, tp):
        return tp.T

    def cost_numeric(self, traj):
        return float(traj.T)
