"""Which rows one solve of an :class:`~optplan.problem.OptProblem` on the B-spline core has:
boundary families fixed by bounds instead of rows, knot rows left out because their inputs are all
fixed, and the velocity control points given rows when the guess or a solve brings them near their
limit (the others are checked exactly after the solve). The decisions are numbers on the cached
structure of :mod:`.spline_core`; the solve driver is :mod:`.spline_solve`."""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..geometry.banded import solve_banded_dense
from .sparse import SparseMatrix, gram
from .spline_core import Family, SplineCore
from .spline_problem import fixed_boundary
from .terms import JointBoundary

__all__ = ["RowSelection", "VELOCITY_ACTIVATION"]

#: With a fixed duration, a velocity control point's entry gets its rows when the guess brings it
#: past this fraction of its limit (the others are checked after the solve) [-].
VELOCITY_ACTIVATION = 0.5


class RowSelection:
    """The row decisions of a :class:`~.spline_solve.SplineBackend` (its base class): fixed
    boundary families, constant knot rows, the velocity entries with rows."""

    prob: Any
    core: SplineCore | None
    fams: list[Family]
    owner: dict[str, list[str]]

    def __init__(self) -> None:
        #: boundary families whose end control points are fixed by bounds instead of rows:
        #: family name -> (variable indices, values, 3 × 3 map) (:func:`~.spline_problem.fixed_boundary`)
        self.fixed: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        #: knot rows left out because their inputs are all fixed and they hold: family name -> knots
        self.constant: dict[str, set[int]] = {}
        self.constant_violation = 0.0   # the largest violation of those rows (within the tolerance)
        self.vel_extra: dict[str, set[int]] = {}   # velocity entries given rows after a solve (on vel_n intervals)
        self.vel_n = 0
        # the violation of a fixed knot's rows by (family, knot, kernel inputs and bounds) (:meth:`_constant_rows`)
        self._constant_memo: dict[tuple[str, int, bytes], float] = {}

    # ------------------------------------------------------------------ fixed and constant rows
    def _fixed_families(self, core: SplineCore) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """The ``JointBoundary`` families that determine their end's three control points
        exactly (q, q̇ and q̈ given; with a free duration only at rest): those points become fixed
        variables (equal bounds, removed by IPOPT) and the family has no rows."""
        out: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        if not self.prob.fix_boundary_points:
            return out
        for h in self.prob._handles:
            if h.role != "constraint" or not isinstance(h.term, JointBoundary):
                continue
            got = fixed_boundary(core, h.term, self.prob.duration)
            if got is not None:
                for name in self.owner.get(h.name, ()):
                    out[name] = got
        return out

    def _fit_between_fixed(self, P: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """With both ends' control points fixed (:meth:`_fixed_families`, the duration of the
        guess the problem's): the interior points P_3 … P_N−1 whose knot values are closest (least
        squares) to the guess's knots ``Q`` [rad] between those ends, as the fixed variables will
        have them (an interpolation ringing up to the fixed ends costs the solve iterations)."""
        core = self.core
        assert core is not None
        fixed = self._fixed_families(core)
        N, nj = core.N, core.nj
        idx = set().union(*[set(v[0].tolist()) for v in fixed.values()]) if fixed else set()
        if N < 4 or not idx.issuperset(range(3 * nj)) or not idx.issuperset(range(N * nj, (N + 3) * nj)):
            return P
        flat = P.ravel().copy()
        for i, v, _ in fixed.values():
            flat[i] = v
        Pf = flat.reshape(N + 3, nj)
        A = np.asarray(core.M["q"][1:N], float)
        ends = np.r_[0:3, N:N + 3]
        rhs = Q[1:N] - SparseMatrix.from_dense(A[:, ends]) @ Pf[ends]
        B = A[:, 3:N]
        # normal equations of a banded system: banded (a dense solve is slow under a loaded BLAS);
        # the products summed in the order of a sparse product (over B's rows), not BLAS's
        Pf[3:N] = solve_banded_dense(gram(B), gram(B, rhs)).reshape(N - 3, nj)
        return Pf

    def row_families(self) -> list[Family]:
        """The families that have rows in the NLP: those fixed by bounds have none, and a knot
        whose inputs are all fixed loses the rows :meth:`_constant_rows` found held."""
        out = []
        for f in self.fams:
            if f.name in self.fixed:
                continue
            drop = self.constant.get(f.name)
            out.append(f if not drop else dataclasses.replace(f, points=[k for k in f.points if k not in drop]))
        return out

    def _fixed_knots(self) -> list[int]:
        """Knots whose every kernel input is fixed: an end whose three control points a boundary
        fixes, with a fixed duration, and for a floating robot only the start (the end's base
        attitude is a variable)."""
        core = self.core
        assert core is not None
        if core.free_time or not self.fixed:
            return []
        idx = set().union(*[set(v[0].tolist()) for v in self.fixed.values()])
        nj, N = core.nj, core.N
        ends = [(0, range(0, 3 * nj))] + ([] if core.fl else [(N, range(N * nj, (N + 3) * nj))])
        return [k for k, r in ends if idx.issuperset(r)]

    def _constant_rows(self, x: np.ndarray, p: np.ndarray, tol: float) -> dict[str, set[int]]:
        """Rows of knot families at :meth:`_fixed_knots` are constants (no variable left in
        them): those that hold within ``tol`` are left out of the NLP (empty rows make its
        Jacobian rank-deficient), by family name → knots; one that does not hold keeps its rows,
        so that the solve reports the problem infeasible. ``x`` has the fixed values."""
        core = self.core
        assert core is not None
        out: dict[str, set[int]] = {}
        self.constant_violation = 0.0
        for k in self._fixed_knots():
            for f in self.fams:
                if f.kind != "knot" or f.cost or f.fn is None or f.name in self.fixed or k not in f.points:
                    continue
                inputs = np.asarray(core.knot_inputs(x, p, k, False), float)
                # a kernel is a function of its inputs: the same inputs and bounds, the same violation
                key = (f.name, k, inputs.tobytes() + np.asarray(f.lower, float).tobytes() + np.asarray(f.upper, float).tobytes())
                viol = self._constant_memo.get(key)
                if viol is None:
                    v = np.asarray(f.fn(inputs)).ravel()
                    viol = float(np.max(np.maximum(np.maximum(f.lower - v, v - f.upper), 0.0), initial=0.0))
                    self._constant_memo[key] = viol
                if viol <= tol:
                    out.setdefault(f.name, set()).add(k)
                    self.constant_violation = max(self.constant_violation, viol)
        return out

    # ------------------------------------------------------------------ velocity rows
    def _velocity_families(self) -> list[Family]:
        return [f for f in self.fams if f.kind == "velocity"]

    def _activation(self, f: Family) -> float:
        """The velocity activation [fraction of the limit] of the term that owns family ``f``."""
        for h in self.prob._handles:
            if f.name in self.owner.get(h.name, ()):
                a = getattr(h.term, "activation", None)
                return VELOCITY_ACTIVATION if a is None else float(a)
        return VELOCITY_ACTIVATION


    def _velocity_points(self, x: np.ndarray) -> np.ndarray:
        """Velocity control points [rad/s] of ``x``, (N+2) × nj."""
        core = self.core
        assert core is not None
        T = core.duration_of(x, self.prob.duration)
        return np.diff(core.control_points(x), axis=0) * core.N / T

    def _select_velocity(self, x: np.ndarray) -> None:
        """With a fixed duration, a velocity entry gets its two rows when the guess ``x`` brings it
        past ``VELOCITY_ACTIVATION`` of its limit (as the segment NLP), or when an earlier solve of
        this structure exceeded its limit there; the rest are checked after every solve
        (:meth:`_missed_velocity`). The velocity control points bound the velocity everywhere
        (convex hull), so the check is exact."""
        assert self.core is not None
        if self.vel_n != self.core.N:     # a new grid (refinement): the entries of the old one mean nothing
            self.vel_extra, self.vel_n = {}, self.core.N
        V = self._velocity_points(x).ravel()
        for f in self._velocity_families():
            lo, hi = (np.tile(b, self.core.N + 2) for b in np.asarray(f.data))
            a = self._activation(f)
            on = (V >= a * hi) | (V <= a * lo)
            f.points = sorted(set(np.flatnonzero(on).tolist()) | self.vel_extra.get(f.name, set()))

    def _missed_velocity(self, x: np.ndarray, tol: float) -> bool:
        """After a solve: give rows to the entries without one that exceed their limit (and to
        those past ``VELOCITY_ACTIVATION`` of it); True if any was added (the problem is re-solved)."""
        core = self.core
        assert core is not None
        if core.free_time:
            return False
        V = self._velocity_points(x).ravel()
        added = False
        for f in self._velocity_families():
            lo, hi = (np.tile(b, core.N + 2) for b in np.asarray(f.data))
            has = np.zeros(V.size, bool)
            has[np.asarray(f.points, int)] = True
            if not np.any(~has & ((V > hi + tol) | (V < lo - tol))):
                continue
            a = self._activation(f)
            on = ~has & ((V >= a * hi) | (V <= a * lo))
            extra = self.vel_extra.setdefault(f.name, set())
            extra.update(np.flatnonzero(on).tolist())
            f.points = sorted(set(f.points) | extra)
            added = True
        return added
