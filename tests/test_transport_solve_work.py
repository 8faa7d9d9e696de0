"""The work of one transport solve on the kernel core (``optplan bench modelling``'s ``transport``,
N = 50, written with the public ``OptProblem`` API), counted instead of timed: IPOPT iterations
and the derivative callbacks per iteration, with the result checked independently (coal
clearance, the closed chain through Pinocchio: ``verify``)."""
from __future__ import annotations

import pytest
from transport_case import transport

from optplan.problem import nlp as nlp_mod


@pytest.fixture
def ipopt_stats(monkeypatch):
    """IPOPT's statistics of every NLP solve while the test runs (``solver.stats()``)."""
    seen: list[dict] = []
    solve = nlp_mod.NlpSolver.solve

    def spy(self, *args, **kwargs):
        out = solve(self, *args, **kwargs)
        seen.append(self.stats())
        return out

    monkeypatch.setattr(nlp_mod.NlpSolver, "solve", spy)
    return seen


def test_transport_solves_in_few_iterations_with_one_evaluation_per_iteration(ipopt_stats):
    """The bench's transport (N = 50, its first guess from seed 0): 18 IPOPT iterations (IPOPT
    3.14.19, MUMPS 5.8.2; at most 22 allowed), one Hessian per iteration, at most two extra
    Jacobians, on average at most one extra objective/constraint evaluation per iteration (line
    search); the solution holds its 0.02 m margin and the closed chain (coal, Pinocchio)."""
    from optplan.bench.modelling import _forget_memory
    from optplan.verification import verify

    # a structure built earlier in this process shares its compiled functions, whose call counts
    # (solver.stats()) add up over the solves: built afresh, as in a new process
    _forget_memory()
    robot, scene, prob, cc = transport(0)
    sol = prob.solve()
    assert sol.success and sol.attempts and len(sol.attempts) == 1, sol.status
    it = sol.total_iterations
    assert it <= 22
    assert len(ipopt_stats) == 1
    st = ipopt_stats[0]
    assert st["iter_count"] == it
    assert st["n_call_nlp_hess_l"] == it
    assert st["n_call_nlp_jac_g"] <= it + 2
    assert st["n_call_nlp_f"] <= 2 * it + 1 and st["n_call_nlp_g"] <= 2 * it + 1
    rep = verify(robot, sol, scene, closed_chain=cc)
    assert rep.min_clearance_m >= 0.02 - 1e-4
    assert rep.max_closed_chain_residual <= 1e-5
