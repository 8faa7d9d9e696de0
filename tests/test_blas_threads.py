"""IPOPT runs with CasADi's OpenBLAS limited to ``SolverOptions.blas_threads`` threads (its idle
workers spun a second core on every re-solve), and the library's own count is back after the
solve. The count is read inside IPOPT, from an iteration callback."""
from __future__ import annotations

import threading

import casadi as ca
import numpy as np
import pytest

from optplan.errors import OptionError
from optplan.problem import blas_threads as bt
from optplan.problem.nlp import NlpSolver, SolverOptions


class _Probe(ca.Callback):
    """An IPOPT iteration callback that records the OpenBLAS thread count at each iteration."""

    def __init__(self, nx: int, ng: int, lib) -> None:
        ca.Callback.__init__(self)
        self.nx, self.ng, self.lib = nx, ng, lib
        self.seen: list[int] = []
        self.construct("probe", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        n = ca.nlpsol_out(i)
        if n == "f":
            return ca.Sparsity.scalar()
        if n in ("x", "lam_x"):
            return ca.Sparsity.dense(self.nx)
        if n in ("g", "lam_g"):
            return ca.Sparsity.dense(self.ng)
        return ca.Sparsity(0, 0)

    def eval(self, arg):
        self.seen.append(int(self.lib.openblas_get_num_threads()))
        return [0]


def _solver(options: SolverOptions):
    x = ca.SX.sym("x", 3)
    libs = bt.casadi_blas_libraries()
    probe = _Probe(3, 1, libs[0])
    nlp = {"x": x, "f": ca.sumsqr(x - np.array([1.0, 2.0, 3.0])), "g": x[0] + x[1]}
    return NlpSolver("probe", nlp, options, casadi_options={"iteration_callback": probe}), probe, libs[0]


@pytest.fixture
def two_threads():
    """CasADi's OpenBLAS set to 2 threads for the test (a 1-core machine starts at 1), restored after."""
    y = ca.SX.sym("y")
    NlpSolver("load", {"x": y, "f": y ** 2})   # CasADi loads its IPOPT plugin (and BLAS) here
    libs = bt.casadi_blas_libraries()
    if not libs:
        pytest.skip("this CasADi has no OpenBLAS of its own in its package")
    before = [lib.openblas_get_num_threads() for lib in libs]
    for lib in libs:
        lib.openblas_set_num_threads(2)
    yield libs
    for lib, k in zip(libs, before):
        lib.openblas_set_num_threads(k)


def test_ipopt_runs_on_one_blas_thread_and_the_count_is_restored(two_threads):
    solver, probe, lib = _solver(SolverOptions())
    out = solver.solve(np.zeros(3), lbg=-np.inf, ubg=1.0)
    assert out.status.succeeded and probe.seen, out.status
    assert set(probe.seen) == {1}, probe.seen                 # inside IPOPT: the default, one thread
    assert lib.openblas_get_num_threads() == 2                # after it: the library's own count


def test_blas_threads_none_leaves_the_library_alone(two_threads):
    solver, probe, lib = _solver(SolverOptions(blas_threads=None))
    assert solver.solve(np.zeros(3), lbg=-np.inf, ubg=1.0).status.succeeded
    assert set(probe.seen) == {2}, probe.seen
    solver, probe, lib = _solver(SolverOptions(blas_threads=3))
    assert solver.solve(np.zeros(3), lbg=-np.inf, ubg=1.0).status.succeeded
    assert set(probe.seen) == {3} and lib.openblas_get_num_threads() == 2, probe.seen


def test_concurrent_limits_restore_once_the_last_leaves(two_threads):
    lib = two_threads[0]
    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()
    seen: dict[str, int] = {}

    def a():
        with bt.limited_blas_threads(1):
            a_in.set()
            b_in.wait(5)
        a_out.set()

    def b():
        a_in.wait(5)
        with bt.limited_blas_threads(1):
            b_in.set()
            a_out.wait(5)
            seen["b after a left"] = lib.openblas_get_num_threads()

    ts = [threading.Thread(target=a), threading.Thread(target=b)]
    for t in ts:
        t.start()
    for t in ts:
        t.join(10)
    assert seen == {"b after a left": 1}
    assert lib.openblas_get_num_threads() == 2
    with bt.limited_blas_threads(1), bt.limited_blas_threads(1):   # nested
        assert lib.openblas_get_num_threads() == 1
    assert lib.openblas_get_num_threads() == 2


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "1"])
def test_blas_threads_must_be_a_positive_integer(bad):
    with pytest.raises(OptionError, match=r"blas_threads.*expected an integer > 0.*got"):
        SolverOptions(blas_threads=bad)
