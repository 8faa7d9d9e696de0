"""The NLP builds' own sparse matrices (:mod:`optplan.problem.sparse`) against SciPy's, and the
segment NLP built and solved in a fresh process without importing SciPy at all (its import cost
0.2-0.35 s of every ``optplan plan`` process that optimized a segment)."""
from __future__ import annotations

import subprocess
import sys

import casadi as ca
import numpy as np
import pytest
import scipy.sparse as sps

from optplan.problem.sparse import SparseMatrix, as_sparse, to_dm


def _random(rng, shape, n, dup=True, zeros=True):
    r = rng.integers(0, shape[0], n)
    c = rng.integers(0, shape[1], n)
    d = rng.normal(size=n)
    if zeros:
        d[rng.random(n) < 0.1] = 0.0   # explicit zeros stay structural, as in SciPy
    if dup and n > 2:
        r[-2:], c[-2:] = r[0], c[0]     # duplicates are summed
    return d, r, c


def _same(S: SparseMatrix, ref) -> None:
    ref = sps.csc_matrix(ref)
    ref.sum_duplicates()
    ref.sort_indices()
    assert S.shape == ref.shape
    np.testing.assert_array_equal(S.colind(), ref.indptr)
    np.testing.assert_array_equal(S.row, ref.indices)
    np.testing.assert_allclose(S.data, ref.data, rtol=1e-15, atol=0)


@pytest.mark.parametrize("seed", range(6))
def test_construction_products_and_triangles_equal_scipys(seed):
    rng = np.random.default_rng(seed)
    shape = (int(rng.integers(1, 30)), int(rng.integers(1, 30)))
    d, r, c = _random(rng, shape, int(rng.integers(0, 80)))
    S = SparseMatrix(d, r, c, shape)
    ref = sps.csr_matrix((d, (r, c)), shape=shape)
    ref.sum_duplicates()   # (older SciPy keeps the duplicates of a COO input stored until asked)
    _same(S, ref)
    assert S.nnz == ref.nnz
    np.testing.assert_allclose(S.toarray(), ref.toarray(), rtol=1e-15)
    x = rng.normal(size=shape[1])
    X = rng.normal(size=(shape[1], 3))
    np.testing.assert_array_equal(S @ x, ref @ x)   # the same sums in the same order
    np.testing.assert_allclose(S @ X, ref @ X, rtol=1e-14, atol=1e-14)
    _same(S.T, ref.T)
    _same(S.triu(), sps.triu(ref))
    k = int(rng.integers(0, shape[1] + 1))
    _same(S.columns(k), ref[:, :k])
    _same(2.5 * S, 2.5 * ref)
    _same(S * 2, ref * 2)
    d2, r2, c2 = _random(rng, shape, 20)
    d2[:3], r2[:3], c2[:3] = -d[:3], r[:3], c[:3]    # some entries cancel: dropped, as SciPy's sum drops them
    S2, ref2 = SparseMatrix(d2, r2, c2, shape), sps.csr_matrix((d2, (r2, c2)), shape=shape)
    np.testing.assert_allclose((S + S2).toarray(), (ref + ref2).toarray(), rtol=1e-14, atol=1e-15)
    assert np.all((S + S2).data != 0.0)
    _same(S.eliminate_zeros(), ref.multiply(ref != 0))


def test_dense_and_scipy_inputs_and_the_casadi_matrix():
    rng = np.random.default_rng(11)
    A = rng.normal(size=(7, 5))
    A[rng.random(A.shape) < 0.5] = 0.0
    S = SparseMatrix.from_dense(A)
    _same(S, sps.csr_matrix(A))
    assert as_sparse(S) is S
    _same(as_sparse(sps.coo_matrix(A)), sps.csr_matrix(A))
    D = to_dm(S)
    assert D.nnz() == S.nnz == np.count_nonzero(A)
    np.testing.assert_array_equal(np.array(D), A)
    rows, cols = (np.asarray(v) for v in D.sparsity().get_triplet())
    np.testing.assert_array_equal(rows, S.row)
    np.testing.assert_array_equal(cols, S.col)
    assert SparseMatrix.zeros((3, 4)).nnz == 0 and to_dm(SparseMatrix.zeros((3, 4))).shape == (3, 4)
    assert isinstance(ca.mtimes(to_dm(S), ca.DM.ones(5, 1)), ca.DM)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="outside the shape"):
        SparseMatrix([1.0], [3], [0], (3, 3))
    with pytest.raises(ValueError, match="one length"):
        SparseMatrix([1.0, 2.0], [0], [0], (3, 3))
    with pytest.raises(ValueError, match="2-D"):
        SparseMatrix.from_dense(np.ones(3))
    with pytest.raises(ValueError, match=r"\(3, 3\) times \(4,\)"):
        SparseMatrix.from_dense(np.eye(3)) @ np.ones(4)


_NO_SCIPY = """
import sys
import numpy as np
from optplan.model.example_robots import load_robot
from optplan.problem import JointBoundary, JointVelocityLimits, OptProblem, Smoothness
robot = load_robot("tcbirrt_dual_arm")
rng = np.random.default_rng(0)
prob = OptProblem(robot, n_intervals=8, duration=6.0, transcription="bspline")
prob.compile_kernels = False
prob.add_cost(Smoothness("jerk"))
prob.add_cost(Smoothness("acceleration"), weight=0.1)
prob.add_constraint(JointBoundary("start", q=robot.neutral()))
prob.add_constraint(JointBoundary("end", q=robot.neutral() + rng.uniform(-0.3, 0.3, robot.nq)))
prob.add_constraint(JointVelocityLimits())
sol = prob.solve()
assert sol.success, sol.status
print(" ".join(sorted(m for m in sys.modules if m == "scipy" or m.startswith("scipy."))))
"""


def test_a_spline_nlp_is_built_and_solved_without_importing_scipy():
    out = subprocess.run([sys.executable, "-c", _NO_SCIPY], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip() == "", f"imported: {out.stdout.strip()}"


@pytest.mark.parametrize("N", [7, 49, 100, 135])
def test_the_spline_fits_products_equal_scipys_to_the_last_bit(N):
    """The least-squares fit between fixed ends (``spline_rows``) forms ``A_ends @ P``, ``BᵀB`` and
    ``Bᵀ r`` of the B-spline knot matrix: summed in SciPy's order, so its guesses (and the solves
    that start from them) are the same numbers as with SciPy's sparse products."""
    from optplan.problem.bspline import knot_matrices
    from optplan.problem.sparse import gram

    rng = np.random.default_rng(N)
    A = knot_matrices(N)["q"][1:N]
    ends = np.r_[0:3, N:N + 3]
    P = rng.normal(size=(N + 3, 14))
    Q = rng.normal(size=(N - 1, 14))
    S = sps.csr_matrix(A)
    rhs_ref = Q - S[:, ends] @ P[ends]
    rhs = Q - SparseMatrix.from_dense(A[:, ends]) @ P[ends]
    np.testing.assert_array_equal(rhs, rhs_ref)
    B = S[:, 3:N]
    np.testing.assert_array_equal(gram(A[:, 3:N]), (B.T @ B).toarray())
    np.testing.assert_array_equal(gram(A[:, 3:N], rhs), B.T @ rhs)
    with pytest.raises(ValueError, match="gram"):
        gram(np.ones((3, 2)), np.ones((4, 2)))
