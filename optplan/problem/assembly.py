"""Rows of a kernel NLP and their exact constraint Jacobian, assembled from per-point kernel
derivatives: every entry of the NLP's matrices is a fixed linear combination of kernel-derivative
entries (the B-spline weights), applied as one constant sparse matrix (:func:`scatter`). The
B-spline core's local assembly (:mod:`.floating_kernels`) builds on :class:`RowAssembly`."""
from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
import numpy.typing as npt

from .sparse import SparseMatrix, to_dm

__all__ = ["RowAssembly", "nonzeros", "scatter"]


class RowAssembly:
    """The rows of an NLP in order: their expressions, bounds and named slices, and the blocks of
    their Jacobian as ``(row, col, src, weight)`` triplets (``src`` −1: the constant 1) over the
    MX nonzero vectors ``jsrc``. The B-spline core's local assembly
    (:class:`~optplan.problem.floating_kernels._LocalAssembly`) builds on it."""

    def __init__(self) -> None:
        self.g: list[Any] = []  # CasADi row expressions
        # bounds: one vector per block while rows are added; finish() joins them into one np.ndarray
        self.lbg: Any = []
        self.ubg: Any = []
        self.slices: dict[str, slice] = {}
        self.ng = 0
        self.jsrc: list[ca.MX] = []  # MX nonzero vectors
        self.j_off = 0
        self.jt: list[np.ndarray] = []  # (row, col, src, weight) blocks; src −1: constant 1

    def _rows(self, name: str, expr: Any, lo: npt.ArrayLike, hi: npt.ArrayLike) -> int:
        n = expr.shape[0]
        self.g.append(expr)
        self.lbg.append(np.broadcast_to(np.asarray(lo, float), (n,)).copy())
        self.ubg.append(np.broadcast_to(np.asarray(hi, float), (n,)).copy())
        self.slices[name] = slice(self.ng, self.ng + n)
        self.ng += n
        return self.ng - n


def nonzeros(M: ca.MX) -> ca.MX:
    """The structural nonzeros of ``M`` as a column, in CasADi's column-major order. (``M.nz[:]``
    keeps a row's shape: the output of a one-row kernel, e.g. a sphere's plane row, mapped over
    the knots is a row, and a row cannot be stacked with the other families' columns.)"""
    return ca.vec(M.nz[:])


def scatter(nrow: int, ncol: int, rows: np.ndarray, cols: np.ndarray, src_idx: np.ndarray, weights: np.ndarray,
            src: ca.MX, nsrc: int) -> ca.MX:
    """Sparse ``nrow × ncol`` MX whose entry (rows[i], cols[i]) sums ``weights[i]·src[src_idx[i]]``."""
    key = cols.astype(np.int64) * nrow + rows
    uniq, inv = np.unique(key, return_inverse=True)  # sorted column-major = CCS order
    ucol, urow = uniq // nrow, uniq % nrow
    colind = np.searchsorted(ucol, np.arange(ncol + 1)).tolist()
    sp = ca.Sparsity(nrow, ncol, colind, urow.astype(int).tolist())
    if uniq.size == key.size:
        # one source per entry (a constraint Jacobian): the entries are the sources picked and
        # weighted, without the constant matrix (~0.6x the CasADi objects to make; the same values)
        order = np.empty(key.size, np.int64)
        order[np.asarray(inv).ravel()] = np.arange(key.size)
        picked = ca.vec(src[np.asarray(src_idx)[order].astype(int).tolist()])
        w = np.asarray(weights, float)[order]
        return ca.MX(sp, picked if np.all(w == 1.0) else picked * ca.DM(w.tolist()))
    # sorted, unique row indices per column (CasADi < 3.7 needs them)
    Sd = to_dm(SparseMatrix(weights, np.asarray(inv).ravel(), src_idx, (len(uniq), nsrc)))
    return ca.MX(sp, ca.mtimes(Sd, src))


