"""``codegen.call_dense``: a CasADi function evaluated through its buffer gives CasADi's own
numbers for every input form it accepts (whole input, a column or block repeated across a map, a
number, an empty input), falls back to the ordinary call for sparse outputs, and never reads past
an input of the wrong size."""
import casadi as ca
import numpy as np
import pytest

from optplan.codegen import call_dense


def _f():
    x = ca.SX.sym("x", 3)
    P = ca.SX.sym("P", 2, 2)
    t = ca.SX.sym("t")
    e = ca.SX.sym("e", 0, 1)
    return ca.Function("f", [x, P, t, e], [ca.vertcat(ca.sin(x), ca.vec(P @ x[:2]) * t), ca.sumsqr(x) * t])


def test_mapped_inputs_match_casadi():
    rng = np.random.default_rng(7)
    fm = _f().map(5)
    X, Pv, T = rng.normal(size=(3, 5)), rng.normal(size=(2, 2)), 0.7
    got = call_dense(fm, X, Pv, T, np.zeros((0, 5)))
    want = fm(ca.DM(X), ca.DM(Pv), T, ca.DM(0, 5))
    assert [g.shape for g in got] == [(5, 5), (1, 5)]
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, np.array(w))
    # a column repeated across the map, and the whole (2, 10) block
    Pw = rng.normal(size=(2, 10))
    np.testing.assert_array_equal(call_dense(fm, X[:, 0], Pw, np.full(5, T), np.zeros((0, 5)))[0],
                                  np.array(fm(ca.repmat(ca.DM(X[:, 0]), 1, 5), ca.DM(Pw), T, ca.DM(0, 5))[0]))


def test_sparse_output_and_wrong_sizes():
    x = ca.SX.sym("x", 3)
    g = ca.Function("g", [x], [ca.diag(x)])          # a sparse output: CasADi's ordinary call
    v = np.array([1.0, -2.0, 3.0])
    np.testing.assert_array_equal(call_dense(g, v)[0], np.diag(v))
    with pytest.raises(RuntimeError):                   # too few numbers: CasADi's error, no read past them
        call_dense(_f().map(5), np.zeros((3, 4)), np.zeros((2, 2)), 1.0, np.zeros((0, 5)))


class _NoStats:
    """A solver wrapper whose function buffer has no ``stats`` (as CasADi 3.6's)."""

    def __init__(self, solver):
        self._s = solver

    def buffer(self):
        buf, run = self._s.buffer()

        class B:   # the buffer's calls, without statistics
            set_arg, set_res, ret = buf.set_arg, buf.set_res, buf.ret

        return B(), run

    def __getattr__(self, name):
        return getattr(self._s, name)

    def __call__(self, **kw):
        return self._s(**kw)


@pytest.mark.parametrize("no_stats", [False, True])
def test_ipopt_call_with_and_without_buffer_statistics(no_stats):
    """The solver gives the same solution and statistics whether IPOPT is called through a buffer or,
    where the buffer has no statistics (older CasADi), by the ordinary call."""
    from optplan.problem.nlp import NlpSolver

    x = ca.SX.sym("x", 2)
    nlp = {"x": x, "f": (x[0] - 1) ** 2 + (x[1] + 2) ** 2, "g": x[0] + x[1]}
    s = NlpSolver("t", nlp, {"print_level": 0})
    buffered = hasattr(s.solver.buffer()[0], "stats") and not no_stats   # CasADi 3.6's buffers have none
    if no_stats:
        s.solver = _NoStats(s.solver)
    out = s.solve(np.zeros(2), lbg=[-10.0], ubg=[10.0])
    np.testing.assert_allclose(np.ravel(out.x), [1.0, -2.0], atol=1e-7)
    assert out.iterations >= 1 and s.stats()["success"]
    assert (s._buffer is not False) == buffered
