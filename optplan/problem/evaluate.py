"""Evaluating a problem's terms at a solution through their handles (Drake's bindings on a
``MathematicalProgramResult``): values, bound violations, multipliers, values along the
continuous trajectory, and the worst rows. A :class:`TermEvaluator` is a snapshot of one build
of an :class:`~optplan.problem.OptProblem`; every :class:`~optplan.problem.Solution` the problem
returns carries the one it was solved with."""
from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .build import TermData
from .terms import NumericTrajectory

if TYPE_CHECKING:
    from .handles import TermHandle
    from .solution import Solution

#: what names a term: its handle or its name
HandleLike = Any

__all__ = ["TermEvaluator", "Infeasibility"]


@dataclass(frozen=True)
class Infeasibility:
    """One violated constraint row: ``term`` (its name, or ``"dynamics"`` for the transcription's
    own rows), ``row`` (index within the term), ``point`` (knot ``k``, interior point
    ``(k, fraction)``, or None), ``value``, ``lower``, ``upper`` and ``violation`` (≥ 0), in the
    row's physical units."""

    term: str
    row: int
    point: object
    value: float
    lower: float
    upper: float
    violation: float
    #: the row in the user's language (``closed_chain[k=12].rot_y at t=4.8 s``; "" when unnamed)
    label: str = ""

    def __str__(self) -> str:
        if self.label:
            return (f"{self.label}: {self.value:.6g} not in [{self.lower:.6g}, {self.upper:.6g}] "
                    f"(violation {self.violation:.3g})")
        at = "" if self.point is None else f" at {self.point}"
        return (f"{self.term}[{self.row}]{at}: {self.value:.6g} not in [{self.lower:.6g}, {self.upper:.6g}] "
                f"(violation {self.violation:.3g})")


class TermEvaluator:
    """The terms of one build of a problem, evaluated at that build's solutions."""

    def __init__(self, problem: Any, built: dict[str, Any]) -> None:
        # a weak reference: a Solution keeps what evaluates its terms, not the problem's solver
        self._problem = weakref.ref(problem)
        self.robot = problem.robot
        self.floating = bool(problem.tp.floating)
        self.com0 = None if not self.floating else np.array(problem.tp.com0, float)
        self.handles = dict(problem.terms)
        self.data = dict(built["data"])
        self.rows = dict(built["rows"])
        self.gfun, self.costs = built["gfun"], built["costs"]
        self.cost_names = list(built["cost_names"])
        self.lbg, self.ubg = built["lbg"].copy(), built["ubg"].copy()
        self.dyn = built["dyn"]

    @property
    def problem(self) -> Any:
        """The problem this evaluator was built from (None once it no longer exists)."""
        return self._problem()

    # ------------------------------------------------------------------ lookup
    def _binding(self, handle: HandleLike) -> tuple[TermHandle, TermData]:
        name = handle if isinstance(handle, str) else getattr(handle, "name", None)
        if name not in self.handles:
            raise KeyError(f"no term named {name!r} in the problem of this solution (terms: {sorted(self.handles)})")
        h = self.handles[name]
        if not isinstance(handle, str) and handle.term is not h.term \
                and getattr(h.term, "_origin", None) is not handle.term:   # refined by the dense check
            raise KeyError(f"the handle {name!r} refers to a term that was replaced before this solve; use the "
                           "handle replace_term returned (or the name)")
        return h, self.data[name]

    def _constraint(self, handle: HandleLike, what: str) -> tuple[TermHandle, TermData]:
        h, d = self._binding(handle)
        if h.role != "constraint":
            raise TypeError(f"{what}: {h.name!r} is a cost (it has no rows, bounds or multipliers); value() gives "
                            "its cost")
        return h, d

    def _rows(self, h: TermHandle, d: TermData, x: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(values, lower, upper) of a constraint's rows, physical units."""
        x = np.asarray(x, float)
        if d.var_bounds is not None:
            idx, lo, hi = d.var_bounds
            sc = d.var_scale
            return x[idx] / sc, np.asarray(lo) / sc, np.asarray(hi) / sc
        g = np.array(self.gfun(x)).ravel()[self.rows[h.name]]
        return g, np.asarray(d.lower), np.asarray(d.upper)

    # ------------------------------------------------------------------ Solution API
    def value(self, handle: HandleLike, sol: Solution) -> float | np.ndarray:
        h, d = self._binding(handle)
        if h.role == "cost":
            return float(np.array(self.costs(sol.x)).ravel()[self.cost_names.index(h.name)])
        r, _, _ = self._rows(h, d, sol.x)
        return d.shaped(r)

    def violation(self, handle: HandleLike, sol: Solution) -> np.ndarray:
        h, d = self._constraint(handle, "violation")
        r, lo, hi = self._rows(h, d, sol.x)
        return d.shaped(np.maximum(np.maximum(lo - r, r - hi), 0.0))

    def dual(self, handle: HandleLike, sol: Solution) -> np.ndarray:
        h, d = self._constraint(handle, "dual")
        if d.var_bounds is not None:
            if sol.lam_x is None:
                raise ValueError(f"dual: no bound multipliers in this solution (status {sol.status.value})")
            return d.shaped(-np.asarray(sol.lam_x)[d.var_bounds[0]] * d.var_scale)
        if sol.lam_g is None:
            raise ValueError(f"dual: no constraint multipliers in this solution (status {sol.status.value})")
        return d.shaped(-np.asarray(sol.lam_g)[self.rows[h.name]])

    def sample(self, handle: HandleLike, sol: Solution, t: Any) -> np.ndarray:
        h, d = self._binding(handle)
        term = h.term.sampled()
        t = np.atleast_1d(np.asarray(t, float))
        traj = self.sampled_trajectory(sol, t)
        v = np.asarray(term.numeric_built(traj, d), float)
        return v.reshape(t.size, -1)

    def sampled_trajectory(self, sol: Solution, t: np.ndarray) -> NumericTrajectory:
        """:func:`sampled_trajectory` of this evaluator's robot."""
        return sampled_trajectory(self.robot, sol, t, self.com0)

    # ------------------------------------------------------------------ problem API
    def infeasibilities(self, sol: Solution, n: int) -> list[Infeasibility]:
        out: list[Infeasibility] = []
        x = np.asarray(sol.x, float)
        g = np.array(self.gfun(x)).ravel()
        sl = self.dyn
        gd, lo, hi = g[sl], self.lbg[sl], self.ubg[sl]
        v = np.maximum(np.maximum(lo - gd, gd - hi), 0.0)
        for i in np.flatnonzero(v > 0):
            out.append(Infeasibility("dynamics", int(i), None, float(gd[i]), float(lo[i]), float(hi[i]), float(v[i])))
        for name, h in self.handles.items():
            if h.role != "constraint":
                continue
            d = self.data[name]
            r, lo, hi = self._rows(h, d, x)
            v = np.maximum(np.maximum(lo - r, r - hi), 0.0)
            pts = d.row_points()
            for i in np.flatnonzero(v > 0):
                out.append(Infeasibility(name, int(i), pts[i], float(r[i]), float(lo[i]), float(hi[i]), float(v[i])))
        out.sort(key=lambda r: -r.violation)
        return out[:n]


def sampled_trajectory(robot: Any, sol: Solution, t: np.ndarray, com0: Any = None) -> NumericTrajectory:
    """A :class:`NumericTrajectory` whose knots are the times ``t`` [s] of a solution (joints
    exact; a floating base's quaternion normalised-linearly interpolated between knots)."""
    s = sol.sample(t)
    M = t.size
    nj = s["q"].shape[1]
    bq = None
    if sol.base_quat is not None:
        k = np.clip(np.searchsorted(sol.t, t, side="right") - 1, 0, len(sol.t) - 2)
        f = ((t - sol.t[k]) / (sol.t[k + 1] - sol.t[k]))[:, None]
        base_quat = np.asarray(sol.base_quat)
        Q0, Q1 = base_quat[k], base_quat[k + 1]
        Q1 = np.where((np.sum(Q0 * Q1, axis=1) < 0)[:, None], -Q1, Q1)
        bq = (1 - f) * Q0 + f * Q1
        bq /= np.linalg.norm(bq, axis=1, keepdims=True)
    T = float(t[-1] - t[0]) if M > 1 and t[-1] > t[0] else 1.0
    return NumericTrajectory(robot, s["q"], s["qd"], s["qdd"], np.zeros((max(M - 1, 0), nj)), T, bq, com0)
