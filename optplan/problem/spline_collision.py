"""`CollisionAvoidance` on the B-spline kernel core of `OptProblem`: the segment NLP's fixed-normal
separating planes (:mod:`.segment`, decision 0003/0012) — active pairs and knots from the first
guess, one kernel per pair ``f([q; n; s])`` with the plane normal ``n`` and the static side's
support ``s`` as parameters (a moving pair's plane offset: a decision variable).

Pair activation: a term left at the default ``activation`` takes the plane rows' own
(:data:`~optplan.problem.plane_rows.SPLINE_ACTIVATION`, 0.12 m — a third of the
pairs and half the rows of 0.3 m on the transport, decision 0012) and leaves out the *steady*
pairs (:data:`STEADY_PAIRS`: far above the margin at a nearly constant distance all along the
guess); a pair it misses is found by the dense check after the solve (coal, every pair), which
plans the rows again along the solution (steady pairs included) or re-solves on a finer grid. An
explicit ``activation`` is used as given, with every pair below it."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .collision_term import CollisionAvoidance
from .frame_terms import ClosedChain
from .plane_rows import SPLINE_ACTIVATION, PlanePlanner

__all__ = ["CollisionItem", "plan_collision", "STEADY_PAIRS"]

#: ``(band, spread)`` [m]: a term at its default activation gets no rows for a pair whose exact
#: distance at every knot of the guess is at least the margin + ``band`` and varies by at most
#: ``spread`` along it — e.g. a wrist link beside the object its own hand holds, whose distance
#: only the wrist joints change (on the transport 3 of its 4 pairs, 816 of its 1128 plane rows).
STEADY_PAIRS = (0.02, 0.005)


@dataclass
class CollisionItem:
    """One active pair: its local kernel ``f([q; n; s])``, knots, per-knot normals (3 × K), static
    supports or initial plane offsets (K), margins (K), rows per knot, static side or not."""

    name: str
    fn: ca.Function
    knots: list[int]
    normals: np.ndarray
    offsets: np.ndarray
    margins: np.ndarray
    nrow: int
    static: bool


def plan_collision(prob: Any, core: Any, term: CollisionAvoidance, Qk: np.ndarray,
                   lower: np.ndarray, upper: np.ndarray, steady: bool = True) -> tuple[list[CollisionItem], Any]:
    """The active pairs along the knot configurations ``Qk`` ((N+1) × nj) and their kernels
    (:class:`~optplan.problem.plane_rows.PlanePlanner`); the term's ``activate_with`` trajectories
    and ``margin_boost`` are honoured (the retry policy's pair activation and boost). ``steady``:
    a term at its default activation leaves out the steady pairs (:data:`STEADY_PAIRS`); False
    when the rows are planned again along a solution that missed a pair."""
    robot, N = prob.robot, prob.N
    pinned = prob._pinned_q()
    cc = next((h.term for h in prob._handles if h.role == "constraint" and isinstance(h.term, ClosedChain)), None)
    q0, q1 = pinned.get(0, Qk[0]), pinned.get(N, Qk[-1])
    lo = np.where(np.isfinite(lower), lower, robot.lower)
    hi = np.where(np.isfinite(upper), upper, robot.upper)
    default = CollisionAvoidance.__dataclass_fields__["activation"].default
    at_default = term.activation == default
    if at_default:
        term = dataclasses.replace(term, activation=SPLINE_ACTIVATION)
    model = term.model(robot)
    if at_default and steady:
        model.steady = STEADY_PAIRS
    fixed = frozenset(np.flatnonzero(lo == hi).tolist())
    planner = PlanePlanner(robot, model, N, prob.duration, q0, q1, fixed, cc, window=term.window, kernels=core.kc)
    Q = np.array(Qk, float)
    Q[0], Q[-1] = q0, q1
    plan, planes = planner.rows(Q)
    kc, nj = core.kc, robot.nj
    items = []
    for it, (Nrm, s0) in zip(plan, planes):
        fn = it.fn

        def build(name: str, fn: ca.Function = fn) -> ca.Function:
            z = ca.SX.sym("z", nj + 4)
            return ca.Function(name, [z], [fn(z[:nj], z[nj:nj + 3], z[nj + 3])])

        local = kc._get(("local_pair", fn.name()), build)
        items.append(CollisionItem(f"collision:{it.pair.name_a}|{it.pair.name_b}", local, list(it.knots),
                                   np.asarray(Nrm, float), np.asarray(s0, float), np.asarray(it.margins, float),
                                   int(it.nrow), bool(it.static)))
    return items, model
