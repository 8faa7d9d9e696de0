"""Exact constraint Jacobian and Lagrangian Hessian of the B-spline segment NLP (:mod:`.segment`),
assembled from per-knot kernel derivatives: every entry of the NLP's matrices is a fixed linear
combination of kernel-derivative entries (the B-spline weights), applied as one constant sparse
matrix."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np
import numpy.typing as npt

__all__ = ["Assembly", "nonzeros", "scatter"]


_C = (1 / 6, 4 / 6, 1 / 6)  # ∂q(t_k)/∂P_{k+a}, a = 0, 1, 2


class RowAssembly:
    """The rows of an NLP in order: their expressions, bounds and named slices, and the blocks of
    their Jacobian as ``(row, col, src, weight)`` triplets (``src`` −1: the constant 1) over the
    MX nonzero vectors ``jsrc``. :class:`Assembly` (the joint B-spline segment NLP) and the
    floating-base segment NLP's assembly build on it."""

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


class Assembly(RowAssembly):
    """Rows of a segment NLP and their exact Jacobian and Lagrangian Hessian, assembled from the
    per-knot kernel derivatives: every entry of the NLP's matrices is a fixed linear combination
    of kernel-derivative entries (the B-spline weights of the module docstring), applied as one
    constant sparse matrix. Free control point ``p`` (3 ≤ p ≤ N−1), joint ``j`` is variable
    ``(p − 3)·nj + j``."""

    def __init__(self, N: int, nj: int, nx: int):
        super().__init__()
        self.N, self.nj, self.nx = N, nj, nx
        self.points: dict[str, tuple[int, np.ndarray] | None] = {}  # name -> (rows per knot, knots) of a kernel family, None for linear rows
        self.hsrc: list[ca.MX] = []  # MX nonzero vectors
        self.h_off = 0
        self._h_pending: list[tuple[Any, ...]] = []  # per family: what its Hessian block needs (finish)

    def _rows(self, name: str, expr: Any, lo: npt.ArrayLike, hi: npt.ArrayLike) -> int:
        self.points[name] = None  # rows per point: set by family
        return super()._rows(name, expr, lo, hi)

    def linear(self, name: str, expr: Any, D: np.ndarray, lo: npt.ArrayLike, hi: npt.ArrayLike,
               select: np.ndarray | None = None) -> None:
        """Rows ``vec(P Dᵀ)`` (D: rows over the N+3 control points), constant Jacobian; with
        ``select``, only those entries of ``vec(P Dᵀ)`` (entry ``i·nj + j``: row i of D, joint j)
        — ``expr`` must then be the selected entries, in that order."""
        r0 = self._rows(name, expr, lo, hi)
        nj, N = self.nj, self.N
        sel = np.arange(D.shape[0] * nj) if select is None else np.asarray(select, int)
        R, C, W = [], [], []
        for r, e in enumerate(sel):
            i, j = divmod(int(e), nj)
            for pidx in np.flatnonzero(D[i]):
                if 3 <= pidx <= N - 1:
                    R.append(r0 + r)
                    C.append((pidx - 3) * nj + j)
                    W.append(D[i, pidx])
        self.jt.append(np.array([R, C, np.full(len(R), -1), W], float))

    def family(self, name: str, fn: ca.Function, jfn: ca.Function, hfn: ca.Function,
               knots: Sequence[int] | np.ndarray, Qsub: Any, Nin: Any, Sin: Any,
               bcoup: tuple[int, np.ndarray] | None, lo: npt.ArrayLike, hi: npt.ArrayLike) -> None:
        """One kernel evaluated at ``knots`` (its rows are knot-major)."""
        K, nj, N = len(knots), self.nj, self.N
        m = fn.size1_out(0)
        r0 = self._rows(name, ca.vec(fn.map(K)(Qsub, Nin, Sin)), lo, hi)
        knots = np.asarray(knots)
        self.points[name] = (m, knots.copy())
        # Jacobian: row r0 + t·m + lr, column of P_{k+a} joint j, weight c_a
        Jm = jfn.map(K)(Qsub, Nin, Sin)
        lr, jj = (np.asarray(v) for v in jfn.sparsity_out(0).get_triplet())
        e = len(lr)
        self.jsrc.append(nonzeros(Jm))
        t: np.ndarray
        t, a, ee = np.meshgrid(np.arange(K), np.arange(3), np.arange(e), indexing="ij")
        pidx = knots[t] + a
        ok = (pidx >= 3) & (pidx <= N - 1)
        self.jt.append(np.array([(r0 + t * m + lr[ee])[ok], ((pidx - 3) * nj + jj[ee])[ok],
                                 (self.j_off + t * e + ee)[ok], np.take(_C, a)[ok]], float))
        self.j_off += K * e
        if bcoup is not None:  # plane offsets: ∂row/∂b = ±1
            col0, sign = bcoup
            t, lr2 = np.meshgrid(np.arange(K), np.arange(m), indexing="ij")
            self.jt.append(np.array([(r0 + t * m + lr2).ravel(), (col0 + t).ravel(),
                                     np.full(K * m, -1), np.tile(sign, K)], float))
        # Hessian: multipliers of this family, per knot
        self._h_pending.append((hfn, K, knots, Qsub, Nin, Sin, r0, m))

    def finish(self, x: ca.MX, lam_f: ca.MX, lam_g: ca.MX, Hj: np.ndarray) -> tuple[ca.MX, ca.MX, ca.MX]:
        """``(g, ∂g/∂x, triu ∇²L)`` as MX of ``x``, ``lam_f``, ``lam_g``; ``Hj``: the objective's
        constant Hessian per joint over the free control points."""
        nj, N, nx = self.nj, self.N, self.nx
        G = ca.vertcat(*self.g) if self.g else ca.MX.zeros(0)
        self.lbg = np.concatenate(self.lbg) if self.lbg else np.zeros(0)
        self.ubg = np.concatenate(self.ubg) if self.ubg else np.zeros(0)
        # Jacobian
        T = np.hstack(self.jt) if self.jt else np.zeros((4, 0))
        src = ca.vertcat(*self.jsrc, ca.MX(1.0)) if self.jsrc else ca.MX(1.0)
        srcidx = np.where(T[2] < 0, self.j_off, T[2]).astype(int)
        Jg = scatter(self.ng, nx, T[0].astype(int), T[1].astype(int), srcidx, T[3], src, self.j_off + 1)
        # Hessian
        hs, blocks, off = [], [], 0
        for hfn, K, knots, Qsub, Nin, Sin, r0, m in self._h_pending:
            L = ca.reshape(lam_g[r0:r0 + m * K], m, K)
            Hm = hfn.map(K)(Qsub, Nin, Sin, L)
            ii, jj = (np.asarray(v) for v in hfn.sparsity_out(0).get_triplet())
            e = len(ii)
            hs.append(nonzeros(Hm))
            t, a, b, ee = np.meshgrid(np.arange(K), np.arange(3), np.arange(3), np.arange(e), indexing="ij")
            pa, pb = knots[t] + a, knots[t] + b
            row, col = (pa - 3) * nj + ii[ee], (pb - 3) * nj + jj[ee]
            ok = (pa >= 3) & (pa <= N - 1) & (pb >= 3) & (pb <= N - 1) & (row <= col)
            blocks.append(np.array([row[ok], col[ok], (off + t * e + ee)[ok],
                                    (np.take(_C, a) * np.take(_C, b))[ok]], float))
            off += K * e
        # objective: Hj ⊗ I over the free points, times lam_f
        pa, pb = np.nonzero(np.triu(Hj) != 0)
        jj = np.arange(nj)
        rows = (pa[:, None] * nj + jj).ravel()
        cols = (pb[:, None] * nj + jj).ravel()
        blocks.append(np.array([rows, cols, np.full(rows.size, off), np.repeat(Hj[pa, pb], nj)], float))
        src = ca.vertcat(*hs, lam_f)
        T = np.hstack(blocks)
        Hl = scatter(nx, nx, T[0].astype(int), T[1].astype(int), T[2].astype(int), T[3], src, off + 1)
        return G, Jg, Hl


def nonzeros(M: ca.MX) -> ca.MX:
    """The structural nonzeros of ``M`` as a column, in CasADi's column-major order. (``M.nz[:]``
    keeps a row's shape: the output of a one-row kernel, e.g. a sphere's plane row, mapped over
    the knots is a row, and a row cannot be stacked with the other families' columns.)"""
    return ca.vec(M.nz[:])


def scatter(nrow: int, ncol: int, rows: np.ndarray, cols: np.ndarray, src_idx: np.ndarray, weights: np.ndarray,
            src: ca.MX, nsrc: int) -> ca.MX:
    """Sparse ``nrow × ncol`` MX whose entry (rows[i], cols[i]) sums ``weights[i]·src[src_idx[i]]``."""
    import scipy.sparse as sps

    key = cols.astype(np.int64) * nrow + rows
    uniq, inv = np.unique(key, return_inverse=True)  # sorted column-major = CCS order
    ucol, urow = uniq // nrow, uniq % nrow
    S = sps.csc_matrix((weights, (inv, src_idx)), shape=(len(uniq), nsrc))
    S.sum_duplicates()  # CasADi < 3.7 needs sorted, unique row indices per column
    S.sort_indices()
    colind = np.searchsorted(ucol, np.arange(ncol + 1)).tolist()
    sp = ca.Sparsity(nrow, ncol, colind, urow.astype(int).tolist())
    # nonzeros as a list: CasADi converts a Python list ~1.6x faster than an ndarray (measured, 477k entries)
    Sd = ca.DM(ca.Sparsity(S.shape[0], S.shape[1], S.indptr.tolist(), S.indices.tolist()), S.data.tolist())
    return ca.MX(sp, ca.mtimes(Sd, src))


