"""Coarse-to-fine (bisection) orders of the interior checkpoints of an edge: a blocked edge is usually found
after a few checks. The orders and their fraction and index forms are cached per number of cells."""
from __future__ import annotations

import numpy as np

__all__ = ["_bisection_order", "_bisection_array", "_bisection_fractions", "_bisection_indices"]

_ORDERS: dict[int, list[int]] = {}
_ORDER_ARRAYS: dict[int, np.ndarray] = {}


def _bisection_order(n: int) -> list[int]:
    """1..n−1 in coarse-to-fine (bisection) order, so a blocked edge is usually found early."""
    if n not in _ORDERS:
        _ORDERS[n] = _bisection_array(n).tolist()
    return _ORDERS[n]


_ORDER_ARRAY: dict[int, np.ndarray] = {}


def _bisection_array(n: int) -> np.ndarray:
    """:func:`_bisection_order` as an integer array (cached)."""
    got = _ORDER_ARRAY.get(n)
    if got is None:
        # level by level, each interval [lo, hi] (hi − lo ≥ 2) gives its midpoint, then its two halves in
        # order; the midpoints lie strictly inside disjoint intervals, so none repeats
        lo, hi = np.zeros(1, np.int64), np.full(1, int(n), np.int64)
        out: list[np.ndarray] = []
        while lo.size:
            keep = hi - lo >= 2
            if not keep.all():
                lo, hi = lo[keep], hi[keep]
            mid = (lo + hi) // 2
            out.append(mid)
            # the halves [lo, mid], [mid, hi] of each interval, interleaved (slices: cheaper than np.stack)
            nlo, nhi = np.empty(2 * lo.size, np.int64), np.empty(2 * lo.size, np.int64)
            nlo[0::2], nlo[1::2], nhi[0::2], nhi[1::2] = lo, mid, mid, hi
            lo, hi = nlo, nhi
        got = _ORDER_ARRAY[n] = np.concatenate(out)
    return got


def _bisection_fractions(n: int) -> np.ndarray:
    """``k / n`` for the ``k`` of :func:`_bisection_order` (same order), as one array."""
    f = _ORDER_ARRAYS.get(n)
    if f is None:
        f = _ORDER_ARRAYS[n] = _bisection_array(n) / n
    return f


_ORDER_INDICES: dict[int, np.ndarray] = {}


def _bisection_indices(n: int) -> np.ndarray:
    """``k − 1`` for the ``k`` of :func:`_bisection_order` (same order): indices into the n − 1 interior points."""
    f = _ORDER_INDICES.get(n)
    if f is None:
        f = _ORDER_INDICES[n] = _bisection_array(n) - 1
    return f
