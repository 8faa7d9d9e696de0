"""Joint-torque terms of :class:`~optplan.problem.OptProblem`: :class:`JointTorqueLimits` and
:class:`TorqueCost`.

The torques are the recursive Newton-Euler of :mod:`optplan.model.dynamics` evaluated on the
transcription's knot values ``(q_k, q̇_k, q̈_k)``: for a fixed base ``pinocchio.rnea``; for a
free-floating robot the torques that move the joints with zero wrench on the base and zero
momentum. The numeric twins (``numeric``) use Pinocchio's own algorithms (``rnea``, ``crba``,
``computeCentroidalMap``), independent of the CasADi expressions.

Torques are a nonlinear function of the state, so a limit that holds at the knots can be exceeded
between them; ``interior`` adds rows at points inside every interval, and ``OptProblem.solve``
checks every limit densely after the solve (:mod:`optplan.problem.guarantees`).
"""
from __future__ import annotations

import dataclasses
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError
from ..model.dynamics import SymbolicDynamics
from ..model.robot import RobotModel
from .build import BuildContext, TermData
from .expressions import register_quantity
from .terms import NumericTrajectory, Term, _frozen_vector, _set

__all__ = ["JointTorqueLimits", "TorqueCost", "joint_torques_numeric", "effort_limits"]

_DYN: weakref.WeakKeyDictionary[RobotModel, SymbolicDynamics] = weakref.WeakKeyDictionary()
#: effort limits at or above this value are Pinocchio's "no limit" (it stores 1.8e308) [N·m]
_NO_LIMIT = 1e300


def dynamics_of(robot: RobotModel) -> SymbolicDynamics:
    """The (cached) :class:`SymbolicDynamics` of a robot."""
    d = _DYN.get(robot)
    if d is None:
        d = _DYN[robot] = SymbolicDynamics(robot)
    return d


def joint_torques_numeric(robot: RobotModel, qj: np.ndarray, vj: np.ndarray, aj: np.ndarray) -> np.ndarray:
    """Joint torques (nj) [N·m or N] with Pinocchio: ``rnea`` for a fixed base; for a free-floating
    base the base twist from zero momentum (``computeCentroidalMap``) and the base acceleration
    from the base rows of ``M a + h = 0`` (``crba``), then ``rnea``'s joint rows."""
    m, d = robot.model, robot.data
    qj, vj, aj = (np.asarray(x, float) for x in (qj, vj, aj))
    if not robot.is_floating:
        return np.array(pin.rnea(m, d, qj, vj, aj))
    q = np.r_[0, 0, 0, 0, 0, 0, 1.0, qj]
    Ag = pin.computeCentroidalMap(m, d, q)
    v = np.r_[np.linalg.solve(Ag[:, :6], -Ag[:, 6:] @ vj), vj]
    M = pin.crba(m, d, q)
    M = np.triu(M) + np.triu(M, 1).T
    h = pin.rnea(m, d, q, v, np.zeros(m.nv))
    ab = -np.linalg.solve(M[:6, :6], M[:6, 6:] @ aj + h[:6])
    return np.array(pin.rnea(m, d, q, v, np.r_[ab, aj]))[6:]


def effort_limits(robot: RobotModel, limit: Any = None) -> np.ndarray:
    """Per-joint torque limit [N·m or N]: the URDF ``effort`` (``model.effortLimit``), replaced by
    ``limit`` — a scalar, an array (nj) or a dict ``{joint name: limit}`` overriding some joints.
    A joint with neither (effort absent, 0 or infinite) is a ConfigurationError naming it."""
    lim = np.array(robot.model.effortLimit[robot.base_nv:], float)
    names = robot.joint_names
    if isinstance(limit, Mapping):
        for k, v in limit.items():
            if k not in names:
                raise ConfigurationError(f"JointTorqueLimits.limit: unknown joint {k!r} (joints: {list(names)})")
            lim[names.index(k)] = float(v)
    elif limit is not None:
        lim = np.broadcast_to(np.asarray(limit, float), (robot.nj,)).copy()
    bad = [n for n, v in zip(names, lim) if not (np.isfinite(v) and 0 < v < _NO_LIMIT)]
    if bad:
        raise ConfigurationError(f"JointTorqueLimits: no effort limit for joints {bad} of {robot.name!r} (the URDF "
                                 "<limit effort=...> is absent, 0 or infinite); give limit={joint: value [N·m]} or an "
                                 "array")
    return lim


def _points(N: int, interior: int) -> list[Any]:
    """Knots and ``interior`` equally spaced points inside each interval, in time order."""
    pts: list[Any] = []
    for k in range(N + 1):
        pts.append(k)
        if k < N:
            pts += [(k, (i + 1) / (interior + 1)) for i in range(interior)]
    return pts


def _state(tp: Any, pt: Any) -> tuple[Any, Any, Any]:
    """``(q, q̇, q̈)`` expressions at a knot or interior point (exact cubic) of the transcription."""
    if isinstance(pt, int):
        return tp.q(pt), tp.qd(pt), tp.qdd(pt)
    k, f = pt
    tau = tp.h * f
    q, v, a, j = tp.q(k), tp.qd(k), tp.qdd(k), tp.jerk(k)
    return q + tau * v + tau**2 / 2 * a + tau**3 / 6 * j, v + tau * a + tau**2 / 2 * j, a + tau * j


def _check_interior(obj: Any) -> None:
    v = obj.interior
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
        raise ConfigurationError(f"{type(obj).__name__}.interior: expected an integer ≥ 0 (points per interval), "
                                 f"got {v!r}")


@dataclass(eq=False)
class JointTorqueLimits(Term):
    """``|τ_k| ≤ limit`` [N·m or N] for the joint torques at every knot (and ``interior`` points
    per interval).

    limit: None (the URDF ``effort`` of every joint), a scalar, an array (nj) or a dict
    ``{joint name: limit}`` overriding the URDF for some joints; a joint with no limit from either
    is a ConfigurationError when the problem is built. interior: extra rows per interval.
    """

    limit: float | Sequence[float] | np.ndarray | Mapping[str, float] | None = None
    interior: int = 0
    default_name = "torque_limits"

    def _validate(self) -> None:
        _check_interior(self)
        if isinstance(self.limit, Mapping):
            d = {}
            for k, v in self.limit.items():
                if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                        or not (np.isfinite(v) and v > 0):
                    raise ConfigurationError(f"JointTorqueLimits.limit[{k!r}]: expected a finite number > 0 [N·m], "
                                             f"got {v!r}")
                d[str(k)] = float(v)
            import types

            _set(self, "limit", types.MappingProxyType(d))
        elif self.limit is not None:
            a = _frozen_vector(self.limit, "JointTorqueLimits.limit", allow_none=False)
            if np.any(a <= 0):
                raise ConfigurationError(f"JointTorqueLimits.limit: expected values > 0 [N·m], got {self.limit!r}")
            _set(self, "limit", a if a.size > 1 else float(a[0]))

    def limits(self, robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` torques per joint [N·m or N]."""
        lim = effort_limits(robot, self.limit)
        return -lim, lim

    def rows(self, ctx: BuildContext) -> TermData:
        tp = ctx.tp
        lo, hi = self.limits(tp.robot)
        fn = dynamics_of(tp.robot).tau
        pts = _points(tp.N, int(self.interior))
        r = ca.vertcat(*[fn(*_state(tp, p)) for p in pts])
        return TermData(residual=r, lower=np.tile(lo, len(pts)), upper=np.tile(hi, len(pts)), points=tuple(pts),
                        point_rows=tp.nj)

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        """Pinocchio's joint torques at the rows' points of ``traj`` (knots and interior points,
        from the exact piecewise cubic), ``points · nj``."""
        out = []
        for pt in _points(traj.N, int(self.interior)):
            if isinstance(pt, int):
                q, v, a = traj.q[pt], traj.qd[pt], traj.qdd[pt]
            else:
                k, f = pt
                s = f * traj.h
                q0, v0, a0, j0 = traj.q[k], traj.qd[k], traj.qdd[k], traj.jerk[k]
                q, v, a = q0 + s * v0 + s**2 / 2 * a0 + s**3 / 6 * j0, v0 + s * a0 + s**2 / 2 * j0, a0 + s * j0
            out.append(joint_torques_numeric(traj.robot, q, v, a))
        return np.concatenate(out)

    def bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self.limits(traj.robot)
        n = len(_points(traj.N, int(self.interior)))
        return np.tile(lo, n), np.tile(hi, n)

    def sampled(self) -> Term:
        return dataclasses.replace(self, interior=0)


@dataclass(eq=False)
class TorqueCost(Term):
    """``∫ Σ_i w_i τ_i² dt`` [N²·m²·s × weight unit], by Simpson's rule on every interval (the
    torques at the two knots and the interval's midpoint, from the exact piecewise cubic).

    weights: one per joint (nj) or a scalar (default 1); e.g. ``1 / limit²`` to weigh each joint
    by its effort limit.
    """

    weights: float | Sequence[float] | np.ndarray = 1.0
    default_name = "torque_cost"
    cost_only = True

    def _validate(self) -> None:
        a = _frozen_vector(self.weights, "TorqueCost.weights", allow_none=False)
        if np.any(a < 0):
            raise ConfigurationError(f"TorqueCost.weights: expected values ≥ 0, got {self.weights!r}")
        _set(self, "weights", a if a.size > 1 else float(a[0]))

    def _w(self, robot: RobotModel) -> np.ndarray:
        w = np.asarray(self.weights, float)
        if w.size not in (1, robot.nj):
            raise ConfigurationError(f"TorqueCost.weights: expected a scalar or {robot.nj} values, got {w.size}")
        return np.broadcast_to(w, (robot.nj,))

    def cost_expr(self, ctx: BuildContext) -> Any:
        tp = ctx.tp
        w = ca.DM(self._w(tp.robot))
        fn = dynamics_of(tp.robot).tau

        def f(pt: Any) -> Any:
            t = fn(*_state(tp, pt))
            return ca.dot(w, t * t)

        knots = [f(k) for k in range(tp.N + 1)]
        return sum(tp.h / 6 * (knots[k] + 4 * f((k, 0.5)) + knots[k + 1]) for k in range(tp.N))

    def cost_numeric(self, traj: NumericTrajectory) -> float:
        w = self._w(traj.robot)
        h = traj.h

        def f(q: np.ndarray, v: np.ndarray, a: np.ndarray) -> float:
            t = joint_torques_numeric(traj.robot, q, v, a)
            return float(w @ (t * t))

        knots = [f(traj.q[k], traj.qd[k], traj.qdd[k]) for k in range(traj.N + 1)]
        tot = 0.0
        for k in range(traj.N):
            s = h / 2
            q0, v0, a0, j0 = traj.q[k], traj.qd[k], traj.qdd[k], traj.jerk[k]
            mid = f(q0 + s * v0 + s**2 / 2 * a0 + s**3 / 6 * j0, v0 + s * a0 + s**2 / 2 * j0, a0 + s * j0)
            tot += h / 6 * (knots[k] + 4 * mid + knots[k + 1])
        return tot


# --------------------------------------------------------------------------- expressions
_TWIN_CHECKED: weakref.WeakSet[RobotModel] = weakref.WeakSet()


def _checked_torques(s: Any) -> Any:
    """``prob.tau``: the joint torques [N·m or N] at a point (:meth:`SymbolicDynamics.tau`; a
    free-floating base carries no external wrench), checked once per robot against
    :func:`joint_torques_numeric` (Pinocchio) at a random state."""
    robot = s.robot
    f = dynamics_of(robot).tau
    if robot not in _TWIN_CHECKED:
        rng = np.random.default_rng(0)
        lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
        hi = np.where(np.isfinite(robot.upper), robot.upper, np.pi)
        qj, vj, aj = rng.uniform(lo, hi), rng.normal(size=robot.nj), rng.normal(size=robot.nj)
        got = np.asarray(f(qj, vj, aj), float).ravel()
        ref = joint_torques_numeric(robot, qj, vj, aj)
        if not np.allclose(got, ref, rtol=1e-8, atol=1e-8 * (1.0 + np.abs(ref).max())):
            raise ConfigurationError(f"prob.tau: the symbolic joint torques of {robot.name!r} disagree with "
                                     f"Pinocchio's (max |Δ| = {np.abs(got - ref).max():.3g})")
        _TWIN_CHECKED.add(robot)
    return f(s.q, s.qd, s.qdd)


def _base_wrench(s: Any) -> Any:
    """``prob.base_wrench``: ``[F [N]; n [N·m]]`` the robot exerts on its fixed mount
    (:meth:`SymbolicDynamics.base_reaction_wrench`); a floating base has none (an error)."""
    return dynamics_of(s.robot).base_reaction_wrench_function(s.q, s.qd, s.qdd)


register_quantity("tau", _checked_torques)
register_quantity("base_wrench", _base_wrench)
