"""Constant sparse matrices of the NLP builds (input maps, linear rows, quadratic costs, Hessian
scatters), in NumPy: entries in compressed-column order, duplicates summed.

SciPy's sparse matrices did this before; importing ``scipy.sparse`` costs 0.2-0.35 s of every
process that builds a segment NLP (with recent SciPy it imports NumPy's ``testing``, ``f2py`` and
``ma`` through its array-API layer), more than the builds' own use of it. What the builds need is
small: a matrix from triplets or from a dense array, a product with a dense vector or matrix, the
upper triangle, a sum, a column selection, and the CasADi ``DM`` of the same structural nonzeros.
Structural zeros stay as SciPy's ``csr_matrix((data, (row, col)))`` keeps them, until
:meth:`SparseMatrix.eliminate_zeros`. Tests compare every operation with SciPy's.
"""
from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
import numpy.typing as npt

__all__ = ["SparseMatrix", "as_sparse", "gram", "to_dm"]


class SparseMatrix:
    """An ``nrow × ncol`` matrix of float entries ``(row[i], col[i], data[i])``, unique and sorted by
    column, then row (the CasADi/CCS order). Built from triplets whose duplicates are summed."""

    __slots__ = ("shape", "row", "col", "data")

    def __init__(self, data: npt.ArrayLike, row: npt.ArrayLike, col: npt.ArrayLike, shape: tuple[int, int]):
        nrow, ncol = int(shape[0]), int(shape[1])
        if nrow < 0 or ncol < 0:
            raise ValueError(f"SparseMatrix: expected a non-negative shape, got {shape!r}")
        r = np.asarray(row, np.int64).ravel()
        c = np.asarray(col, np.int64).ravel()
        d = np.asarray(data, float).ravel()
        if not (r.size == c.size == d.size):
            raise ValueError(f"SparseMatrix: row, col and data must have one length, got {r.size}, {c.size}, {d.size}")
        if r.size and (r.min() < 0 or r.max() >= nrow or c.min() < 0 or c.max() >= ncol):
            raise ValueError(f"SparseMatrix: an index lies outside the shape {(nrow, ncol)}")
        self.shape = (nrow, ncol)
        key = c * max(nrow, 1) + r
        if key.size > 1 and not np.all(key[1:] > key[:-1]):   # not yet unique and sorted
            uniq, inv = np.unique(key, return_inverse=True)
            d = np.bincount(np.asarray(inv).ravel(), weights=d, minlength=uniq.size)
            r, c = uniq % max(nrow, 1), uniq // max(nrow, 1)
        self.row, self.col, self.data = r, c, d

    @classmethod
    def from_dense(cls, A: npt.ArrayLike) -> SparseMatrix:
        """The nonzero entries of a dense 2-D array."""
        A = np.asarray(A, float)
        if A.ndim != 2:
            raise ValueError(f"SparseMatrix.from_dense: expected a 2-D array, got shape {A.shape}")
        c, r = np.nonzero(A.T)   # column-major: already sorted
        return cls(A[r, c], r, c, A.shape)

    @classmethod
    def zeros(cls, shape: tuple[int, int]) -> SparseMatrix:
        """No structural entries."""
        return cls(np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64), shape)

    @property
    def nnz(self) -> int:
        """Structural entries (explicit zeros included)."""
        return int(self.data.size)

    @property
    def T(self) -> SparseMatrix:
        return SparseMatrix(self.data, self.col, self.row, (self.shape[1], self.shape[0]))

    def colind(self) -> np.ndarray:
        """CCS column pointers (``ncol + 1``)."""
        return np.searchsorted(self.col, np.arange(self.shape[1] + 1))

    def toarray(self) -> np.ndarray:
        out = np.zeros(self.shape)
        np.add.at(out, (self.row, self.col), self.data)
        return out

    def triu(self) -> SparseMatrix:
        """The entries on and above the diagonal."""
        k = self.col >= self.row
        return SparseMatrix(self.data[k], self.row[k], self.col[k], self.shape)

    def columns(self, stop: int) -> SparseMatrix:
        """The first ``stop`` columns (``A[:, :stop]``)."""
        stop = min(int(stop), self.shape[1])
        k = self.col < stop
        return SparseMatrix(self.data[k], self.row[k], self.col[k], (self.shape[0], stop))

    def eliminate_zeros(self) -> SparseMatrix:
        """The same matrix without the entries that are exactly zero."""
        k = self.data != 0.0
        return SparseMatrix(self.data[k], self.row[k], self.col[k], self.shape)

    def __matmul__(self, x: npt.ArrayLike) -> np.ndarray:
        """The product with a dense vector (n,) or matrix (n, k)."""
        x = np.asarray(x, float)
        if x.shape[0] != self.shape[1]:
            raise ValueError(f"SparseMatrix @: {self.shape} times {x.shape}")
        if x.ndim == 1:
            return np.bincount(self.row, weights=self.data * x[self.col], minlength=self.shape[0])
        terms = self.data.reshape((-1,) + (1,) * (x.ndim - 1)) * x[self.col]
        out = np.zeros((self.shape[0],) + x.shape[1:])
        np.add.at(out, self.row, terms)
        return out

    def __add__(self, other: SparseMatrix) -> SparseMatrix:
        """The sum; entries that cancel to zero are dropped (as SciPy's sum does)."""
        if not isinstance(other, SparseMatrix) or other.shape != self.shape:
            return NotImplemented
        return SparseMatrix(np.r_[self.data, other.data], np.r_[self.row, other.row], np.r_[self.col, other.col],
                            self.shape).eliminate_zeros()

    def __mul__(self, s: float) -> SparseMatrix:
        """The product with a scalar (the structure kept)."""
        if not isinstance(s, (int, float, np.integer, np.floating)):
            return NotImplemented
        return SparseMatrix(self.data * float(s), self.row, self.col, self.shape)

    __rmul__ = __mul__

    def __repr__(self) -> str:
        return f"SparseMatrix(shape={self.shape}, nnz={self.nnz})"


def as_sparse(A: Any) -> SparseMatrix:
    """``A`` as a :class:`SparseMatrix`: itself, a dense 2-D array's nonzeros, or a SciPy sparse
    matrix's structural entries (read through its ``tocoo()``; SciPy is not imported here)."""
    if isinstance(A, SparseMatrix):
        return A
    if hasattr(A, "tocoo") and hasattr(A, "shape"):
        C = A.tocoo()
        return SparseMatrix(C.data, C.row, C.col, C.shape)
    return SparseMatrix.from_dense(A)


def to_dm(A: Any) -> ca.DM:
    """``A`` (:func:`as_sparse`) as a CasADi ``DM`` with the same structural nonzeros."""
    S = as_sparse(A)
    # the numbers as lists: CasADi converts a Python list ~1.6x faster than an ndarray (measured, 477k entries)
    return ca.DM(ca.Sparsity(S.shape[0], S.shape[1], S.colind().tolist(), S.row.tolist()), S.data.tolist())


def gram(B: npt.ArrayLike, R: npt.ArrayLike | None = None) -> np.ndarray:
    """``Bᵀ B`` (or ``Bᵀ R``) of a dense ``B`` (m × n) that is mostly zeros, summed row after row of
    ``B`` as a sparse product sums it (so the same numbers to the last bit as SciPy's ``B.T @ B`` of
    its CSR matrix; BLAS sums in another order)."""
    B = np.asarray(B, float)
    R = B if R is None else np.asarray(R, float)
    if B.ndim != 2 or R.ndim != 2 or R.shape[0] != B.shape[0]:
        raise ValueError(f"gram: expected 2-D arrays with one row count, got {B.shape} and {R.shape}")
    out = np.zeros((B.shape[1], R.shape[1]))
    for k in range(B.shape[0]):
        nz = np.flatnonzero(B[k])
        if nz.size:
            rk = R[k]
            out[nz] += B[k, nz, None] * rk[None, :]
    return out
