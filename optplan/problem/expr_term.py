"""A user expression as a term (:class:`ExprTerm`): per-point kernels on the B-spline core
(:mod:`.spline_problem`), or rows at the knots of the knot transcription (parameters at their
values of the build)."""
from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from ..codegen import call_dense
from ..errors import ConfigurationError
from .expressions import Parameter, check_symbols, symbols_of
from .terms import Term

__all__ = ["ExprTerm", "knots_of"]


@dataclass(eq=False)
class ExprTerm(Term):
    """A user expression (:mod:`.expressions`): a constraint ``lower ≤ expr ≤ upper`` at ``at``
    or a cost ``weight · ∫ expr dt`` (``kind="integral"``, trapezoidal at the knots; a vector
    expression's squared norm) or ``weight · expr(T)`` (``kind="end"``)."""

    expr: Any = None
    lower: Any = None
    upper: Any = None
    at: Any = "all"
    kind: str = "constraint"
    weight: Any = 1.0
    params: tuple[Parameter, ...] = ()
    default_name = "expr"

    def _validate(self) -> None:
        if self.kind not in ("constraint", "integral", "end"):
            raise ConfigurationError(f"kind: expected 'integral' or 'end', got {self.kind!r}")
        _NUMERIC.pop(self, None)   # a field changed in place (deprecated): its functions are made again

    # ------------------------------------------------------------------ the knot transcription
    def _function(self, robot: Any, expr: Any) -> ca.Function:
        sym = symbols_of(robot)
        check_symbols(sym, expr, list(self.params), self.default_name)
        return ca.Function("expr", sym.inputs() + [p.sym for p in self.params], [ca.vec(expr)])

    def _args(self, robot: Any, q: Any, qd: Any, qdd: Any, quat: Any, t: Any, T: Any, com0: Any) -> list[Any]:
        """The point's arguments (a floating base: its world quaternion, start attitude identity)."""
        fl = robot.is_floating
        return [q, qd, qdd, quat if fl else ca.DM(0, 1), t, T, ca.DM([0, 0, 0, 1.0]) if fl else ca.DM(0, 1),
                ca.DM(com0) if fl else ca.DM(0, 1)] + [ca.DM(p.value) for p in self.params]

    def _knot_values(self, tp: Any, expr: Any, ks: list[int]) -> list[Any]:
        f = self._function(tp.robot, expr)
        com0 = tp.com0 if tp.floating else None
        return [f(*self._args(tp.robot, tp.q(k), tp.qd(k), tp.qdd(k), tp.base_quat(k), tp.knot_time(k), tp.T, com0))
                for k in ks]

    def _weight(self) -> float:
        w = self.weight
        if isinstance(w, ca.SX):
            fn = ca.Function("w", [p.sym for p in self.params], [w])
            return float(fn(*[ca.DM(p.value) for p in self.params]))
        return float(w)

    def rows(self, ctx: Any) -> Any:
        """The rows at the knots of the knot transcription (parameters at their current values)."""
        from .build import TermData

        tp = ctx.tp
        m = ca.vec(ca.SX(self.expr)).shape[0]
        expr, lo, hi = _bounds(self, m, list(self.params))
        ks = knots_of(self.at, tp.N, self.default_name)
        r = ca.vertcat(*self._knot_values(tp, expr, ks))
        return TermData(residual=r, lower=np.tile(lo, len(ks)), upper=np.tile(hi, len(ks)), points=tuple(ks),
                        point_rows=int(expr.shape[0]))

    def _integrand(self) -> Any:
        e = ca.SX(self.expr)
        return e if e.numel() == 1 else ca.sumsqr(e)

    def cost_expr(self, ctx: Any) -> Any:
        tp = ctx.tp
        if self.kind == "end":
            return self._weight() * self._knot_values(tp, self._integrand(), [tp.N])[0]
        v = self._knot_values(tp, self._integrand(), list(range(tp.N + 1)))
        return self._weight() * tp.h * (sum(v[1:-1]) + (v[0] + v[-1]) / 2)

    def _numeric_function(self, robot: Any, what: str) -> tuple[ca.Function, dict[Any, Any]]:
        """The function of this term's rows (``what="rows"``) or integrand (``"integrand"``) at one
        point, and its maps by number of points: made once per term and robot (a re-solve's
        dense check and ``sample`` build no Function)."""
        per = _NUMERIC.get(self)
        if per is None:
            per = _NUMERIC[self] = {}
        got = per.get((id(robot), what))
        if got is None or got[0]() is not robot:
            if what == "rows":
                expr = _bounds(self, ca.vec(ca.SX(self.expr)).shape[0], list(self.params))[0]
            else:
                expr = self._integrand()
            got = per[(id(robot), what)] = (weakref.ref(robot), self._function(robot, expr), {})
        return got[1], got[2]

    def reads_base_attitude(self, robot: Any) -> bool:
        """Whether the expression depends on a floating base's attitude (its world quaternion,
        the start attitude or the centre of mass that places the base): frames and the centre of
        mass do, joint quantities do not."""
        if not robot.is_floating:
            return False
        what = "rows" if self.kind == "constraint" else "integrand"
        f, maps = self._numeric_function(robot, what)
        if "base" not in maps:   # kept with the function's maps (keys: numbers of points)
            maps["base"] = any(f.which_depends(f.name_in(i), [f.name_out(0)], 1, True)[0] for i in (3, 6, 7))
        return bool(maps["base"])

    def _numeric_values(self, traj: Any, what: str, ks: list[int]) -> np.ndarray:
        """The rows (``what="rows"``) or integrand of the expression at the points ``ks`` of
        ``traj``, point after point (one mapped call)."""
        if not ks:
            return np.zeros(0)
        f, maps = self._numeric_function(traj.robot, what)
        k = np.asarray(ks, int)
        fm = maps.get(k.size)
        if fm is None:
            fm = maps[k.size] = f.map(k.size)

        def cols(a: Any) -> np.ndarray:
            return np.asarray(a, float)[k].T

        fl = traj.robot.is_floating
        none = np.zeros((0, k.size))
        args = [cols(traj.q), cols(traj.qd), cols(traj.qdd),
                cols(traj.base_quat) if fl and traj.base_quat is not None else none, (k * traj.T / traj.N)[None, :],
                traj.T, np.array([0, 0, 0, 1.0]) if fl else none, np.asarray(traj.com0, float) if fl else none]
        args += [np.asarray(p.value, float) for p in self.params]
        return call_dense(fm, *args)[0].ravel(order="F")

    def numeric(self, traj: Any) -> np.ndarray:
        return self._numeric_values(traj, "rows", knots_of(self.at, traj.N, self.default_name))

    def bounds_numeric(self, traj: Any) -> tuple[np.ndarray, np.ndarray]:
        per = _NUMERIC.get(self)
        if per is None:
            per = _NUMERIC[self] = {}
        got = per.get((0, "bounds"))   # numbers of the term's fields: made once
        if got is None:
            got = per[(0, "bounds")] = (None, *_bounds(self, ca.vec(ca.SX(self.expr)).shape[0], list(self.params))[1:])
        lo, hi = got[1], got[2]
        n = len(knots_of(self.at, traj.N, self.default_name))
        return np.tile(lo, n), np.tile(hi, n)

    def cost_numeric(self, traj: Any) -> float:
        if self.kind == "end":
            return self._weight() * float(self._numeric_values(traj, "integrand", [traj.N])[0])
        v = self._numeric_values(traj, "integrand", list(range(traj.N + 1)))
        return self._weight() * float(np.trapezoid(v, np.linspace(0, traj.T, traj.N + 1)))

    def sampled(self) -> Term:
        if self.at == "all":
            return self
        return super().sampled()


#: the numeric functions of an expression term, per term: (id(robot), what) -> (robot, the
#: function at one point, its maps by number of points) (:meth:`ExprTerm._numeric_function`);
#: (0, "bounds") -> (None, lower, upper) of the rows
_NUMERIC: weakref.WeakKeyDictionary[ExprTerm, dict[tuple[int, str], tuple[Any, Any, Any]]] = weakref.WeakKeyDictionary()


def knots_of(at: Any, N: int, what: str) -> list[int]:
    """Knot indices of ``at``: "all", "start", "end", "interior", an index or a list."""
    if isinstance(at, str):
        table = {"all": list(range(N + 1)), "start": [0], "end": [N], "interior": list(range(1, N))}
        if at not in table:
            raise ConfigurationError(f"{what}: at: expected 'all', 'start', 'end', 'interior' or knot indices, "
                                     f"got {at!r}")
        return table[at]
    ks = np.atleast_1d(np.asarray(at))
    if ks.dtype.kind not in "iu" or ks.ndim != 1 or ks.size == 0 or ks.min() < -N - 1 or ks.max() > N:
        raise ConfigurationError(f"{what}: at: expected knot indices in [0, {N}], got {at!r}")
    return sorted({int(k) % (N + 1) for k in ks})


def _bounds(term: ExprTerm, m: int, params: list[Parameter]) -> tuple[Any, np.ndarray, np.ndarray]:
    """Rows and numeric bounds of a constraint expression; symbolic bounds (parameters) move
    into the rows."""
    expr = ca.vec(ca.SX(term.expr))
    lo, hi = term.lower, term.upper
    sym_lo = isinstance(lo, (ca.SX, Parameter))
    sym_hi = isinstance(hi, (ca.SX, Parameter))
    if isinstance(lo, Parameter):
        lo = lo.sym
    if isinstance(hi, Parameter):
        hi = hi.sym
    if sym_lo or sym_hi:
        if lo is hi or (sym_lo and sym_hi and ca.is_equal(ca.SX(lo), ca.SX(hi), 2)):
            return expr - ca.vec(ca.SX(lo)) * ca.DM.ones(m), np.zeros(m), np.zeros(m)
        rows, l_, u_ = [], [], []
        for b, sign in ((lo, 1.0), (hi, -1.0)):
            if b is None:
                continue
            if isinstance(b, ca.SX):
                rows.append(sign * (expr - ca.vec(b) * ca.DM.ones(m)))
                l_.append(np.zeros(m))
                u_.append(np.full(m, np.inf))
            else:
                bb = np.broadcast_to(np.asarray(b, float).ravel(order="F"), (m,))
                rows.append(sign * expr)
                l_.append(sign * bb)
                u_.append(np.full(m, np.inf))
        return ca.vertcat(*rows), np.concatenate(l_), np.concatenate(u_)

    def num(b: Any, default: float) -> np.ndarray:
        if b is None:
            return np.full(m, default)
        a = np.asarray(b, float).ravel(order="F")
        if a.size not in (1, m) or np.any(np.isnan(a)):
            raise ConfigurationError(f"bounds: expected a number or {m} numbers, got {b!r}")
        return np.broadcast_to(a, (m,)).copy()

    L, U = num(lo, -np.inf), num(hi, np.inf)
    if lo is None and hi is None:
        raise ConfigurationError("add_constraint: give lower and/or upper for an expression")
    if np.any(L > U):
        raise ConfigurationError(f"bounds: lower > upper at rows {np.flatnonzero(L > U).tolist()}")
    return expr, L, U
