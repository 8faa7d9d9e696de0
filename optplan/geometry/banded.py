"""Banded linear systems solved with numpy alone (Gaussian elimination with partial pivoting, as
LAPACK's ``gbsv``), so that the spline fits of a plan do not import ``scipy.linalg`` and
``scipy.sparse.linalg`` (~0.1 s of start-up together on top of ``scipy.sparse``, measured in the
``optplan plan`` command). The systems here are small (tens to hundreds of unknowns, a few
diagonals): one pass over the rows with a few numpy operations on a (kl+1) × (kl+ku+1) block each.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigurationError

__all__ = ["solve_banded", "solve_banded_dense"]


def solve_banded(l_and_u: tuple[int, int], ab: ArrayLike, b: ArrayLike) -> np.ndarray:
    """``x`` with ``A x = b`` for a banded ``A`` (n × n) given in LAPACK's band storage, the layout
    of ``scipy.linalg.solve_banded``: ``ab[ku + i - j, j] = A[i, j]``, ``ab`` of shape
    (kl + ku + 1, n). ``b``: (n,) or (n, k). Raises ``numpy.linalg.LinAlgError`` for a singular
    matrix, :class:`~optplan.errors.ConfigurationError` for shapes that do not fit. The units of
    ``x`` are those of ``b`` divided by those of ``A``."""
    kl, ku = (int(v) for v in l_and_u)
    ab = np.asarray(ab, float)
    if kl < 0 or ku < 0 or ab.ndim != 2 or ab.shape[0] != kl + ku + 1:
        raise ConfigurationError(f"ab: expected shape ({kl + ku + 1}, n) for (kl, ku) = ({kl}, {ku}), got {ab.shape}")
    n = ab.shape[1]
    rhs = np.array(b, dtype=float)   # a copy: eliminated in place
    if rhs.shape[:1] != (n,):
        raise ConfigurationError(f"b: expected {n} rows to match ab's {n} columns, got shape {rhs.shape}")
    vec = rhs.ndim == 1
    rhs = rhs.reshape(n, -1)
    off = kl + ku                     # the diagonal's row in the working storage (kl rows of fill-in above)
    w = np.zeros((2 * kl + ku + 1, n))
    w[kl:] = ab
    width = kl + ku + 1
    r_all, c_all = np.arange(kl + 1)[:, None], np.arange(width)[None, :]
    for j in range(n):
        nr, nc = min(kl + 1, n - j), min(width, n - j)
        ri = off + r_all[:nr] - c_all[:, :nc]          # (row j + r, column j + c) in the working storage
        ci = np.broadcast_to(j + c_all[:, :nc], ri.shape)
        blk = w[ri, ci]
        p = int(np.argmax(np.abs(blk[:, 0])))
        if blk[p, 0] == 0.0:
            raise np.linalg.LinAlgError(f"singular banded matrix (zero pivot in column {j})")
        if p:
            blk[[0, p]] = blk[[p, 0]]
            rhs[[j, j + p]] = rhs[[j + p, j]]
        if nr > 1:
            lm = blk[1:, 0] / blk[0, 0]
            blk[1:] -= lm[:, None] * blk[0]
            rhs[j + 1:j + nr] -= lm[:, None] * rhs[j]
        w[ri, ci] = blk
    x = np.empty_like(rhs)
    for j in range(n - 1, -1, -1):   # U has kl + ku diagonals above its own
        c = np.arange(j + 1, min(n, j + width))
        x[j] = (rhs[j] - w[off + j - c, c] @ x[c]) / w[off, j]
    return x[:, 0] if vec else x


def solve_banded_dense(A: ArrayLike, b: ArrayLike) -> np.ndarray:
    """``x`` with ``A x = b`` for a square ``A`` given dense whose nonzeros lie on a few diagonals
    (its bandwidths read from its nonzeros), by :func:`solve_banded`."""
    A = np.asarray(A, float)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ConfigurationError(f"A: expected a square matrix, got shape {A.shape}")
    n = A.shape[0]
    i, j = np.nonzero(A)
    kl = int(max(0, (i - j).max(initial=0)))
    ku = int(max(0, (j - i).max(initial=0)))
    ab = np.zeros((kl + ku + 1, n))
    ab[ku + i - j, j] = A[i, j]
    return solve_banded((kl, ku), ab, b)
