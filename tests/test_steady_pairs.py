"""Steady collision pairs on the B-spline core (``spline_collision.STEADY_PAIRS``): a term at its
default activation gets no plane rows for a pair whose exact distance stays far above the margin
at a nearly constant value all along the first guess; the dense check after the solve still
guards every pair, and a pair left out wrongly is planned again along the solution. Counted and
checked against coal distances and ``verify``, not timed."""
from __future__ import annotations

import numpy as np
import pytest
from transport_case import transport

from optplan.problem import spline_collision


@pytest.fixture
def plans(monkeypatch):
    """(steady flag, knot configurations, collision model, items) of every collision plan."""
    seen: list[tuple[bool, np.ndarray, object, list]] = []
    plan = spline_collision.plan_collision

    def spy(prob, core, term, Qk, lower, upper, steady=True):
        items, model = plan(prob, core, term, Qk, lower, upper, steady=steady)
        seen.append((steady, np.array(Qk), model, items))
        return items, model

    monkeypatch.setattr(spline_collision, "plan_collision", spy)
    return seen


def test_transport_leaves_out_exactly_the_steady_pairs_and_keeps_its_margin(plans):
    """On the transport's guess the pairs left out are exactly those whose coal distance (every
    pair, every knot, computed here) stays below the activation, at least margin + band and
    within the spread; the others close to it keep their rows, and the solution holds the margin
    (verify: coal, every pair, between the knots) in one attempt."""
    from optplan.problem.plane_rows import SPLINE_ACTIVATION
    from optplan.verification import verify

    robot, scene, prob, cc = transport(0)
    sol = prob.solve()
    assert sol.success and len(sol.attempts) == 1, sol.status
    assert len(plans) == 1
    steady, Qk, model, items = plans[0]
    assert steady and model.steady == spline_collision.STEADY_PAIRS
    band, spread = spline_collision.STEADY_PAIRS
    chk = model.checker
    D = np.array([chk.distances(q) for q in Qk])   # (N+1) × pairs, exact
    close = (D < SPLINE_ACTIVATION).any(axis=0)
    want = {chk.pairs[i] for i in np.flatnonzero((D < SPLINE_ACTIVATION).all(axis=0)
                                                  & (D.min(axis=0) >= model.margin + band)
                                                  & (np.ptp(D, axis=0) <= spread))}
    assert set(model.steady_pairs) == want and len(want) >= 2
    kept = {chk.pairs[i] for i in np.flatnonzero(close)} - want - set(model.constant_pairs)
    assert kept and kept <= set(model.active_pairs)
    assert not set(model.active_pairs) & want
    rows = sum(len(it.knots) * it.nrow for it in items)
    assert rows < 400, rows   # 1128 plane rows with the steady pairs
    rep = verify(robot, sol, scene, closed_chain=cc)
    assert rep.min_clearance_m >= model.margin - 1e-4
    assert rep.max_closed_chain_residual <= 1e-5


def test_a_pair_left_out_wrongly_is_planned_again_along_the_solution(plans, monkeypatch):
    """Every pair counted steady (band −1 m, any spread): the obstacle pair the guess crosses gets
    no rows, the first solution collides, the dense check finds it, the rows are planned again
    along that solution with no pair left out, and the result holds the margin (verify)."""
    from optplan.verification import verify

    monkeypatch.setattr(spline_collision, "STEADY_PAIRS", (-1.0, np.inf))
    robot, scene, prob, cc = transport(0)
    sol = prob.solve()
    assert sol.success, sol.status
    assert len(plans) >= 2 and len(sol.attempts) >= 2
    first, again = plans[0], plans[1]
    assert first[0] and not first[3]            # no rows at all in the first plan
    assert not again[0] and again[3] and not again[2].steady_pairs
    names = {it.name for it in again[3]}
    assert "collision:object|hanging_box" in names
    rep = verify(robot, sol, scene, closed_chain=cc)
    assert rep.min_clearance_m >= 0.02 - 1e-4
