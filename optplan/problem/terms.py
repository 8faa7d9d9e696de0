"""The term library of :class:`OptProblem`.

A term is a frozen, validated configuration (a frozen dataclass; bad values are refused when it
is created, naming the value). :meth:`Term.build` turns it into :class:`~.build.TermData` for one
NLP, given a :class:`~.build.BuildContext`. Its constraint form is a residual ``r`` (a vector of
CasADi expressions of the transcription) with bounds ``lower ≤ r ≤ upper``. Added with ``add_constraint`` the bounds are enforced; added with
``add_cost`` the cost is ``weight · Σ (r − clip(r, lower, upper))²`` — the squared bound violation
(for equality terms, ``Σ (r − target)²``) — unless the term defines its own cost (smoothness, path
length, duration). Every term also evaluates the same residual **numerically with Pinocchio**
(``numeric``), independent of the CasADi expressions; the tests compare the two over a registry.

Pose residuals avoid Euler angles: position error plus ``vee(E − Eᵀ)/2`` of the rotation error
``E = R_targetᵀ R`` (= sin θ · axis), together with ``trace(E) ≥ 1`` (θ ≤ 90°) so that the spurious
θ = 180° zero is excluded.
"""
from __future__ import annotations

import dataclasses
import types
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, cast, overload

import casadi as ca
import numpy as np

from ..errors import ConfigurationError
from ..geometry.spatial import pose_residual
from ..model.robot import RobotModel
from .build import AuxVariable, BuildContext, TermData
from .numeric_trajectory import NumericTrajectory, pose_residual_numeric, pose_residuals
from .transcription import Expr, Transcription

__all__ = [
    "Term", "JointBoundary", "JointPositionLimits", "JointVelocityLimits", "JointAccelerationLimits", "Smoothness",
    "PathLength", "Duration", "NumericTrajectory", "pose_residual", "pose_residual_numeric", "pose_residuals", "BuildContext",
    "TermData",
]


# --------------------------------------------------------------------------- helpers


def _check_at(at: Any, what: str, allowed: tuple[str, ...] = ("all", "start", "end")
              ) -> str | int | tuple[int, ...]:
    """A knot selection: one of ``allowed``, an int, or a non-empty list of ints (frozen as a tuple)."""
    if isinstance(at, str):
        if at not in allowed:
            raise ConfigurationError(f"{what}: expected one of {allowed}, a knot index or a list of them, got {at!r}")
        return at
    if isinstance(at, (int, np.integer)) and not isinstance(at, bool):
        return int(at)
    try:
        ks = tuple(at)
    except TypeError:
        raise ConfigurationError(f"{what}: expected one of {allowed}, a knot index or a list of them, "
                                 f"got {at!r}") from None
    if not ks or not all(isinstance(k, (int, np.integer)) and not isinstance(k, bool) for k in ks):
        raise ConfigurationError(f"{what}: expected a non-empty list of knot indices, got {at!r}")
    return tuple(int(k) for k in ks)


@overload
def _frozen_vector(v: Any, what: str, allow_none: Literal[False]) -> np.ndarray: ...
@overload
def _frozen_vector(v: Any, what: str, allow_none: bool = True) -> np.ndarray | None: ...
def _frozen_vector(v: Any, what: str, allow_none: bool = True) -> np.ndarray | None:
    """A finite 1-D float array (read-only) or None."""
    if v is None:
        if allow_none:
            return None
        raise ConfigurationError(f"{what}: expected a vector, got None")
    from ..errors import real_array

    a = np.array(real_array(v, what), float)
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1 or not np.all(np.isfinite(a)):
        raise ConfigurationError(f"{what}: expected a finite 1-D vector, got {v!r}")
    a.flags.writeable = False
    return a


def _set(obj: object, name: str, value: object) -> None:
    """Normalise a field of a frozen term in its _validate."""
    object.__setattr__(obj, name, value)


def _knots(at: str | int | Sequence[int], N: int) -> list[int]:
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
    """Base class of the terms: a frozen configuration. Subclasses are ``@dataclass(eq=False)``
    and validate (and normalise, with ``object.__setattr__``) their fields in ``_validate``;
    after ``__init__`` a term is frozen: ``dataclasses.replace(term, field=value)`` makes a changed
    copy. (Assigning a field in place still works for code written before terms were frozen,
    with a DeprecationWarning, and is validated again; it will become
    ``dataclasses.FrozenInstanceError``.)

    :meth:`build` (what :class:`OptProblem` calls) returns the term's :class:`TermData` for one
    NLP. A subclass implements either

    * ``residual(tp) -> (expr, lower, upper)`` — rows in the transcription's expressions, for a
      term that needs nothing but the transcription; or
    * ``rows(ctx) -> TermData`` — when it needs the context (initial guess, pinned knots, fixed
      joints) or auxiliary variables;

    and ``numeric(traj)`` / ``bounds_numeric(traj)``: the same rows evaluated numerically with
    Pinocchio, independently of the CasADi expressions (the tests compare the two). A cost-only
    term implements ``cost_expr(ctx)`` and ``cost_numeric(traj)``.
    """

    default_name = "term"
    cost_only = False
    constraint_only = False

    def __post_init__(self) -> None:
        self._validate()
        object.__setattr__(self, "_frozen", True)

    def _validate(self) -> None:
        """Check (and normalise) the fields; raise ConfigurationError naming the bad value."""

    def __setattr__(self, name: str, value: Any) -> None:
        if self.__dict__.get("_frozen"):
            warnings.warn(f"{type(self).__name__}.{name} = ...: terms are frozen configurations; changing one in "
                          f"place is deprecated and will raise dataclasses.FrozenInstanceError — use "
                          f"dataclasses.replace(term, {name}=...) (and OptProblem.replace_term)",
                          DeprecationWarning, stacklevel=2)
            object.__setattr__(self, name, value)
            self._validate()
            return
        object.__setattr__(self, name, value)

    def __getstate__(self) -> dict[str, Any]:
        return {k: dict(v) if isinstance(v, types.MappingProxyType) else v
                for k, v in self.__dict__.items() if k != "_legacy"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        for k, v in state.items():
            object.__setattr__(self, k, v)
        self._validate()             # normalises (read-only mappings, arrays) again

    # ------------------------------------------------------------------ build (model → data)
    def build(self, ctx: BuildContext) -> TermData:
        """The term's data for one NLP: its rows (``ctx.role == "constraint"``) or its cost."""
        if ctx.role == "cost":
            return TermData(cost=self.cost_expr(ctx))
        if self.cost_only:
            raise TypeError(f"{type(self).__name__} is a cost-only term; use add_cost")
        return self.rows(ctx)

    def rows(self, ctx: BuildContext) -> TermData:
        """The constraint rows (default: from :meth:`residual`)."""
        r, lo, hi = self.residual(ctx.tp)
        return TermData(residual=r, lower=lo, upper=hi)

    def residual(self, tp: Transcription) -> tuple[Expr, np.ndarray, np.ndarray]:
        raise TypeError(f"{type(self).__name__} is a cost-only term: it has no residual/constraint form")

    def cost_expr(self, ctx: BuildContext) -> Expr:
        """The cost expression (default: squared bound violation of the rows; ``Σ (r − target)²``
        for equality rows)."""
        d = self.rows(dataclasses.replace(ctx, role="constraint"))
        r, lo, hi = d.residual, d.lower, d.upper
        assert lo is not None and hi is not None  # narrowing only: constraint rows carry their bounds
        viol = []
        for i in range(r.shape[0]):
            if lo[i] == hi[i]:
                viol.append(r[i] - lo[i])
            else:
                if np.isfinite(hi[i]):
                    viol.append(ca.fmax(r[i] - hi[i], 0))
                if np.isfinite(lo[i]):
                    viol.append(ca.fmin(r[i] - lo[i], 0))
        return ca.sumsqr(ca.vertcat(*viol))

    def cost(self, tp: Transcription) -> Expr:
        """The cost expression on a bare transcription (no initial guess, no pinned knots)."""
        return self.cost_expr(BuildContext(tp, role="cost"))

    def reseed(self, data: TermData, traj: NumericTrajectory) -> tuple[AuxVariable, ...]:
        """``data.aux`` re-seeded for a new initial guess ``traj`` (the problem's structure kept);
        terms without auxiliary variables return them unchanged."""
        return data.aux

    # ------------------------------------------------------------------ numeric (Pinocchio) evaluation
    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        raise TypeError(f"{type(self).__name__} is a cost-only term: it has no residual form")

    def numeric_built(self, traj: NumericTrajectory, data: TermData) -> np.ndarray:
        """:meth:`numeric` for the rows a build produced (``data``); the same unless the build
        made choices (e.g. a collision term's active pairs)."""
        return self.numeric(traj)

    def bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` of the rows :meth:`numeric` returns."""
        raise TypeError(f"{type(self).__name__} is a cost-only term: it has no bounds")

    def _bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:  # the name used before bounds_numeric
        return self.bounds_numeric(traj)

    def cost_numeric(self, traj: NumericTrajectory) -> float:
        """Numeric value of the cost (default: squared bound violation of ``numeric``)."""
        r = self.numeric(traj)
        lo, hi = self.bounds_numeric(traj)
        return float(np.sum(np.where(lo == hi, r - lo, np.maximum(r - hi, 0) + np.minimum(r - lo, 0)) ** 2))

    def reads_base_attitude(self, robot: RobotModel) -> bool:
        """Whether :meth:`numeric` reads a floating base's attitude (``traj.base_quat``): the
        dense check integrates the base between knots only for terms that do. Joint terms do not;
        the default (True) is the safe answer for a term that places frames in the world."""
        return bool(robot.is_floating)

    def sampled(self) -> Term:
        """The term evaluated point by point along a trajectory (what ``Solution.sample`` runs
        ``numeric`` of, on a trajectory whose knots are the sample times). Terms tied to given
        knots (boundaries, poses at a knot) have none."""
        raise TypeError(f"{type(self).__name__} is evaluated at given knots, not along the trajectory: "
                        "sample() applies to terms imposed at every knot (limits, closed chain, orientation, "
                        "collision, paths given as a function of time)")


# --------------------------------------------------------------------------- joint terms
@dataclass(eq=False)
class JointBoundary(Term):
    """Joint values at the start or end knot: any of ``q`` [rad], ``qd`` [rad/s], ``qdd`` [rad/s²]."""

    at: str = "start"
    q: Sequence[float] | np.ndarray | None = None
    qd: Sequence[float] | np.ndarray | None = None
    qdd: Sequence[float] | np.ndarray | None = None
    default_name = "boundary"

    def _validate(self) -> None:
        if self.at not in ("start", "end"):
            raise ConfigurationError(f"JointBoundary.at: expected 'start' or 'end', got {self.at!r}")
        for n in ("q", "qd", "qdd"):
            _set(self, n, _frozen_vector(getattr(self, n), f"JointBoundary.{n}"))
        if self.q is None and self.qd is None and self.qdd is None:
            raise ConfigurationError("JointBoundary: give at least one of q, qd, qdd")

    def knot(self, N: int) -> int:
        return 0 if self.at == "start" else N

    def _parts(self, N: int) -> tuple[int, list[tuple[str, Sequence[float] | np.ndarray]]]:
        return self.knot(N), [(n, v) for n, v in (("q", self.q), ("qd", self.qd), ("qdd", self.qdd)) if v is not None]

    def residual(self, tp: Transcription) -> tuple[Expr, np.ndarray, np.ndarray]:
        k, parts = self._parts(tp.N)
        exprs, targets = [], []
        for n, v in parts:
            v = tp.robot.check_joints(v, f"JointBoundary.{n}")
            exprs.append({"q": tp.q, "qd": tp.qd, "qdd": tp.qdd}[n](k))
            targets.append(v)
        t = np.concatenate(targets)
        return ca.vertcat(*exprs), t, t

    def rows(self, ctx: BuildContext) -> TermData:
        r, lo, hi = self.residual(ctx.tp)
        k, parts = self._parts(ctx.N)
        return TermData(residual=r, lower=lo, upper=hi, points=(k,), point_rows=int(r.shape[0]))

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        k, parts = self._parts(traj.N)
        return np.concatenate([getattr(traj, n)[k] for n, _ in parts])

    def bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:
        k, parts = self._parts(traj.N)
        t = np.concatenate([np.asarray(v, float) for _, v in parts])
        return t, t


@dataclass(eq=False)
class _JointBox(Term):
    lower: Sequence[float] | None = None
    upper: Sequence[float] | None = None
    which = "q"

    def _validate(self) -> None:
        name = type(self).__name__
        for n in ("lower", "upper"):
            _set(self, n, _frozen_vector(getattr(self, n), f"{name}.{n}"))
        lower = cast("np.ndarray | None", self.lower)  # normalised by _frozen_vector just above
        upper = cast("np.ndarray | None", self.upper)
        if lower is not None and upper is not None and lower.shape == upper.shape \
                and np.any(lower > upper):
            raise ConfigurationError(f"{name}: lower > upper at joints {np.flatnonzero(lower > upper).tolist()}")

    def limits(self, robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` per joint in physical units for ``robot``."""
        raise TypeError(f"{type(self).__name__} is abstract: use JointPositionLimits, "
                        "JointVelocityLimits or JointAccelerationLimits")

    def _lims(self, robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:  # the name used before ``limits``
        return self.limits(robot)

    def residual(self, tp: Transcription) -> tuple[Expr, np.ndarray, np.ndarray]:
        lo, hi = self.limits(tp.robot)
        get = {"q": tp.q, "qd": tp.qd, "qdd": tp.qdd}[self.which]
        ks = range(tp.N + 1)
        return ca.vertcat(*[get(k) for k in ks]), np.tile(lo, len(ks)), np.tile(hi, len(ks))

    def rows(self, ctx: BuildContext) -> TermData:
        r, lo, hi = self.residual(ctx.tp)
        return TermData(residual=r, lower=lo, upper=hi, points=tuple(range(ctx.N + 1)), point_rows=ctx.tp.nj)

    def build(self, ctx: BuildContext) -> TermData:
        """As a constraint this term is a plain bound on knot variables (IPOPT treats variable
        bounds much more cheaply than general constraints): ``var_bounds`` = (indices into x,
        lower, upper) in the scaled decision variables."""
        if ctx.role == "cost":
            return super().build(ctx)
        tp = ctx.tp
        lo, hi = self.limits(tp.robot)
        nj, N = tp.nj, tp.N
        block = {"q": 0, "qd": 1, "qdd": 2}[self.which]
        idx = block * nj * (N + 1) + np.arange(nj * (N + 1))
        sc = tp.variable_scale(self.which)  # the variables are scaled (transcription docstring)
        return TermData(var_bounds=(idx, sc * np.tile(lo, N + 1), sc * np.tile(hi, N + 1)), var_scale=sc,
                        points=tuple(range(N + 1)), point_rows=nj)

    def bounds_on(self, tp: Transcription) -> tuple[Any, ...] | None:
        """``(indices into x, lower, upper)``: the variable bounds of :meth:`build`."""
        return self.build(BuildContext(tp)).var_bounds

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        return getattr(traj, self.which).reshape(-1)

    def reads_base_attitude(self, robot: RobotModel) -> bool:
        return False

    def bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self.limits(traj.robot)
        return np.tile(lo, traj.N + 1), np.tile(hi, traj.N + 1)

    def sampled(self) -> Term:
        return self


@dataclass(eq=False)
class JointPositionLimits(_JointBox):
    """``lower ≤ q_k ≤ upper`` at every knot [rad] (default: the robot's limits)."""

    default_name = "joint_limits"
    which = "q"

    def limits(self, robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
        lo = robot.lower if self.lower is None else robot.check_joints(self.lower, "lower")
        hi = robot.upper if self.upper is None else robot.check_joints(self.upper, "upper")
        return lo, hi


def _override(obj: _JointBox, robot: RobotModel, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(lower, upper)``: the term's own ``lower``/``upper`` where given, else ``lo``/``hi``."""
    lo = lo if obj.lower is None else robot.check_joints(obj.lower, f"{type(obj).__name__}.lower")
    hi = hi if obj.upper is None else robot.check_joints(obj.upper, f"{type(obj).__name__}.upper")
    if np.any(lo > hi):
        raise ConfigurationError(f"{type(obj).__name__}: lower > upper at joints {np.flatnonzero(lo > hi).tolist()} "
                                 f"(lower {lo.tolist()}, upper {hi.tolist()})")
    return np.asarray(lo, float), np.asarray(hi, float)


def _check_limit(obj: JointVelocityLimits | JointAccelerationLimits, allow_none: bool) -> None:
    name = type(obj).__name__
    if obj.limit is None and allow_none:
        return
    a = _frozen_vector(obj.limit, f"{name}.limit", allow_none=False)
    if np.any(a < 0):
        raise ConfigurationError(f"{name}.limit: expected values ≥ 0, got {obj.limit!r}")
    _set(obj, "limit", a if a.size > 1 else float(a[0]))


@dataclass(eq=False)
class JointVelocityLimits(_JointBox):
    """``|q̇_k| ≤ limit`` [rad/s] (default: the robot's velocity limits); ``lower``/``upper``
    override."""

    limit: Sequence[float] | np.ndarray | float | None = None
    #: On the B-spline with a fixed duration, a velocity control point's entry gets its rows when
    #: the first guess brings it past this fraction of its limit (the others are checked after
    #: each solve and given rows when one is exceeded) [-, 0-1]; None: 0.5; 0: every entry.
    activation: float | None = None
    default_name = "velocity_limits"
    which = "qd"

    def _validate(self) -> None:
        super()._validate()
        _check_limit(self, allow_none=True)
        a = self.activation
        if a is not None and (isinstance(a, bool) or not isinstance(a, (int, float, np.integer, np.floating))
                              or not 0 <= a <= 1):
            raise ConfigurationError(f"JointVelocityLimits.activation: expected a fraction of the limit in [0, 1] "
                                     f"or None, got {a!r}")

    def limits(self, robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
        lim = robot.velocity_limit if self.limit is None else np.broadcast_to(
            np.asarray(self.limit, float), (robot.nj,))
        return _override(self, robot, -lim, lim)


@dataclass(eq=False)
class JointAccelerationLimits(_JointBox):
    """``|q̈_k| ≤ limit`` [rad/s²] at every knot (q̈ is piecewise linear, so knots bound it);
    ``lower``/``upper`` override."""

    limit: Sequence[float] | float = 1.0
    default_name = "acceleration_limits"
    which = "qdd"

    def _validate(self) -> None:
        super()._validate()
        _check_limit(self, allow_none=False)

    def limits(self, robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
        lim = np.broadcast_to(np.asarray(self.limit, float), (robot.nj,))
        return _override(self, robot, -lim, lim)


# --------------------------------------------------------------------------- cost-only terms
@dataclass(eq=False)
class Smoothness(Term):
    """Integral of a squared derivative: ``"jerk"`` (∫‖j‖² dt = h Σ‖j_k‖², exact),
    ``"acceleration"`` (∫‖q̈‖² dt, exact for the piecewise-linear q̈) or ``"velocity"``
    (∫‖q̇‖² dt, exact for the piecewise-quadratic q̇)."""

    order: str = "jerk"
    default_name = "smoothness"
    cost_only = True

    def _validate(self) -> None:
        if self.order not in ("jerk", "acceleration", "velocity"):
            raise ConfigurationError(f"Smoothness.order: expected 'jerk', 'acceleration' or 'velocity', "
                                     f"got {self.order!r}")

    def cost_expr(self, ctx: BuildContext) -> Expr:
        tp = ctx.tp
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

    def cost_numeric(self, traj: NumericTrajectory) -> float:
        from scipy.integrate import quad_vec

        N, h = traj.N, traj.h

        def integrand(t: float) -> float:
            k = min(int(t / h), N - 1)
            tau = t - k * h
            v0, a0, j0 = traj.qd[k], traj.qdd[k], traj.jerk[k]
            val = {"jerk": j0, "acceleration": a0 + tau * j0, "velocity": v0 + tau * a0 + tau**2 / 2 * j0}[self.order]
            return float(val @ val)

        return float(sum(quad_vec(integrand, k * h, (k + 1) * h)[0] for k in range(N)))


@dataclass(eq=False)
class PathLength(Term):
    """Joint-space path length ``Σ_k sqrt(‖q_{k+1} − q_k‖² + ε²) − ε`` [rad] (smoothed at 0)."""

    eps: float = 1e-6
    default_name = "path_length"
    cost_only = True

    def _validate(self) -> None:
        if isinstance(self.eps, bool) or not isinstance(self.eps, (int, float, np.floating)) \
                or not (np.isfinite(self.eps) and self.eps > 0):
            raise ConfigurationError(f"PathLength.eps: expected a finite number > 0 [rad], got {self.eps!r}")

    def cost_expr(self, ctx: BuildContext) -> Expr:
        tp = ctx.tp
        return sum(ca.sqrt(ca.sumsqr(tp.Q[:, k + 1] - tp.Q[:, k]) + self.eps**2) - self.eps for k in range(tp.N))

    def cost_numeric(self, traj: NumericTrajectory) -> float:
        d = np.diff(traj.q, axis=0)
        return float(np.sum(np.sqrt(np.sum(d**2, axis=1) + self.eps**2) - self.eps))


@dataclass(eq=False)
class Duration(Term):
    """Total duration ``T`` [s] (a cost for free-final-time problems)."""

    default_name = "duration"
    cost_only = True

    def cost_expr(self, ctx: BuildContext) -> Expr:
        return ctx.tp.T

    def cost_numeric(self, traj: NumericTrajectory) -> float:
        return float(traj.T)


_FRAME_TERMS = ("BaseAttitude", "ClosedChain", "FramePath", "FramePose", "OrientationConstraint")


def __getattr__(name: str) -> Any:
    # the frame terms live in .frame_terms (which imports this module); the old path warns
    if name in _FRAME_TERMS:
        from .._compat import moved

        return moved(__name__, name, "optplan.problem")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
