"""Terms as models, their built rows as data (the Crocoddyl model/data split).

A term (:class:`~optplan.problem.terms.Term`) is a frozen configuration: what to constrain or
penalise, validated when it is created. :meth:`Term.build` turns it into :class:`TermData` for
one NLP, given a :class:`BuildContext` — the transcription (variables and the kinematic
expressions terms are written in), the initial guess, the knots a boundary pins and the joints
held fixed. Nothing is written onto the transcription or the term: everything a build produces
(rows, bounds, cost, auxiliary variables, information such as the active collision pairs) is in
the returned data, which :class:`~optplan.problem.OptProblem` assembles into the NLP.
"""
from __future__ import annotations

import types
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

__all__ = ["BuildContext", "AuxVariable", "TermData"]


@dataclass(frozen=True)
class BuildContext:
    """What a term is built against.

    tp: the :class:`~optplan.problem.transcription.Transcription` (layout, ``q(k)``, ``frame``…).
    role: ``"constraint"`` or ``"cost"``.
    initial: the initial guess as a :class:`~optplan.problem.terms.NumericTrajectory` (None
        before ``set_initial``).
    pinned_q: knots whose joints a JointBoundary constraint fixes, ``{k: q [rad]}``.
    fixed_joints: joint-vector indices a JointPositionLimits constraint holds at lower == upper.
    """

    tp: Any
    role: str = "constraint"
    initial: Any = None
    pinned_q: Mapping[int, np.ndarray] = field(default_factory=dict)
    fixed_joints: frozenset[int] = frozenset()

    def __post_init__(self) -> None:
        if self.role not in ("constraint", "cost"):
            raise ValueError(f"BuildContext.role: expected 'constraint' or 'cost', got {self.role!r}")
        object.__setattr__(self, "pinned_q", types.MappingProxyType(dict(self.pinned_q)))
        object.__setattr__(self, "fixed_joints", frozenset(self.fixed_joints))

    @property
    def robot(self) -> Any:
        return self.tp.robot

    @property
    def N(self) -> int:
        return int(self.tp.N)


def _vec(v: Any, n: int, what: str) -> np.ndarray:
    a = np.broadcast_to(np.asarray(v, float), (n,)).copy()
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class AuxVariable:
    """An auxiliary decision variable a term needs (e.g. a separating plane ``(n, b)``): its
    symbol (``casadi.MX``, a column of ``n`` entries), initial value and bounds."""

    name: str
    sym: Any
    init: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def create(cls, name: str, n: int, init: Any, lower: Any = -np.inf, upper: Any = np.inf) -> AuxVariable:
        return cls(name, ca.MX.sym(name, n), _vec(init, n, "init"), _vec(lower, n, "lower"), _vec(upper, n, "upper"))

    @property
    def size(self) -> int:
        return int(self.sym.shape[0])


@dataclass(frozen=True)
class TermData:
    """A built term.

    residual, lower, upper: constraint rows ``lower ≤ residual ≤ upper`` (a ``casadi.MX`` column
        and arrays of its length); ``None`` for a pure cost.
    cost: the (unweighted) cost expression of a term added with ``add_cost``.
    aux: auxiliary variables the rows use (appended to the decision vector in this order).
    var_bounds: for a term that is a plain bound on decision variables — ``(indices into x,
        lower, upper)`` in decision-variable units — and ``var_scale`` (decision variable =
        ``var_scale`` × physical value).
    points, point_rows: the rows are ``point_rows`` consecutive rows per point (a knot ``k`` or
        an interior point ``(k, fraction)``), for per-knot values and reports.
    info: anything else the build decided (e.g. ``active_pairs`` of a collision term).
    """

    residual: Any = None
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    cost: Any = None
    aux: tuple[AuxVariable, ...] = ()
    var_bounds: tuple[Any, ...] | None = None
    var_scale: float = 1.0
    points: tuple[Any, ...] | None = None
    point_rows: int | None = None
    info: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.residual is not None:
            n = int(self.residual.shape[0])
            object.__setattr__(self, "lower", _vec(self.lower if self.lower is not None else 0.0, n, "lower"))
            object.__setattr__(self, "upper", _vec(self.upper if self.upper is not None else 0.0, n, "upper"))
            if self.points is not None and self.point_rows is not None and len(self.points) * self.point_rows != n:
                raise ValueError(f"TermData: {len(self.points)} points × {self.point_rows} rows ≠ {n} rows")
        object.__setattr__(self, "aux", tuple(self.aux))
        object.__setattr__(self, "info", types.MappingProxyType(dict(self.info)))

    @property
    def n_rows(self) -> int:
        if self.var_bounds is not None:
            return int(len(self.var_bounds[0]))
        return 0 if self.residual is None else int(self.residual.shape[0])

    def row_points(self) -> list[Any]:
        """The point (knot ``k`` or ``(k, fraction)``) of every row, or ``None`` per row when unknown."""
        n = self.n_rows
        if self.points is None or not self.point_rows:
            return [None] * n
        return [p for p in self.points for _ in range(self.point_rows)]

    def shaped(self, values: np.ndarray) -> np.ndarray:
        """``values`` (one per row) shaped ``(points, rows per point)`` when the rows are per point."""
        v = np.asarray(values)
        if self.points is not None and self.point_rows and v.size == len(self.points) * self.point_rows:
            return v.reshape(len(self.points), self.point_rows)
        return v
