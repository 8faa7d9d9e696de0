"""The RRT tree every tree planner here grows: nodes in arrays that grow geometrically, parent
indices, optional per-node columns (other coordinates of the same node, e.g. the manifold
parameters next to the joints) and per-node edge payloads (the intermediate configurations of the
edge from the parent), brute-force nearest neighbour, path extraction, and subtree deletion
(lazy edge checking).

Nearest neighbour is the squared Euclidean distance in the key coordinates ``X`` computed with one
``einsum`` over the live nodes: measured (see docs/oc_rrt.md) against ``((X - x)**2).sum(1)``
(1.3-5x slower) and against cached squared norms with one matrix-vector product
(``|X|² − 2 X·x``, 1.5-3x faster from ~1000 nodes on) — the latter was not taken because it
rounds differently and can pick another node among near-ties, which changes the planners'
results on fixed seeds; the search is a few per cent of an iteration (IK, collision checks).

When the native extension library builds (:func:`optplan.planners.kernel.extend.nearest`), the same
search runs as a linear scan in C over the contiguous key array: the same distances term by term, the
first node among equals, 2-3x cheaper than the ``einsum`` (ctypes call included) from a hundred
nodes on; without a C compiler the ``einsum`` stays. A tree class with :attr:`Tree.KD_INDEX` (TCBiRRT's trees) also
keeps a k-d index of its keys, which the native search uses from 512 nodes on: the same answers (the same sums, an
exact pruning bound, the first node among equals), 2-5x fewer distance computations on large trees. It takes new
rows lazily at the next query, so nodes added by native code need no hook.
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["Tree", "joined_path"]

_NATIVE_NN: list[Any] = []   # [the native nearest function or None], decided at the first search


def _native_nearest() -> Any:
    if not _NATIVE_NN:
        try:
            from .kernel.extend import nearest, nearest_available

            _NATIVE_NN.append(nearest if nearest_available() else None)
        except ImportError:   # pragma: no cover - the kernel package ships with optplan
            _NATIVE_NN.append(None)
    return _NATIVE_NN[0]


class Tree:
    """A rooted tree; node 0 is the root.

    ``Tree(root, cap=256, edges=False, **columns)``: ``root`` is the root's key coordinates (what
    :meth:`nearest` measures), ``columns`` the root's values of other per-node arrays, each
    available as an attribute of the same name (e.g. ``Tree(q, P=p)`` → ``tree.P[i]``).
    ``edges=True`` keeps a per-node edge payload (``tree.edge[i]``: anything, default ``[]``),
    the intermediate configurations of the edge from the parent for :meth:`branch`.
    """

    #: Keep a k-d index of the keys for the native nearest-neighbour search (the same answers, far fewer distances in a
    #: large tree). Only for trees whose nodes are never taken back (``n`` never lowered, keys never rewritten).
    KD_INDEX = False

    def __init__(self, root: Any, cap: int = 256, *, edges: bool = False, **columns: Any) -> None:
        root = np.asarray(root, float)
        if root.ndim != 1:
            raise ValueError(f"Tree: expected a 1-D root, got shape {root.shape}")
        if not (isinstance(cap, int) and cap >= 1):
            raise ValueError(f"Tree: expected a capacity >= 1, got {cap!r}")
        self.X = np.empty((cap, root.size))
        self.X[0] = root
        self.parent = np.empty(cap, dtype=np.int64)
        self.parent[0] = -1
        self._cols = tuple(columns)
        for name, v in columns.items():
            v = np.asarray(v)
            a = np.empty((cap, *v.shape), dtype=v.dtype if v.dtype != object else float)
            a[0] = v
            setattr(self, name, a)
        self.edge: list[Any] | None = [[]] if edges else None
        #: the keys' k-d index ``(K, kdn)`` for the native nearest-neighbour search (:attr:`KD_INDEX`), or None
        self.kd: tuple[np.ndarray, np.ndarray] | None = None
        if self.KD_INDEX and _native_nearest() is not None:
            from .kernel.extend import kd_index

            self.kd = kd_index(cap, self.X.shape[1])
        self.alive: np.ndarray | None = None     # created by the first kill()
        self.n_dead = 0
        self.n = 1

    def __len__(self) -> int:
        return self.n

    def _grow(self) -> None:
        def double(a: np.ndarray) -> np.ndarray:
            return np.concatenate([a, np.empty_like(a)])
        self.X = double(self.X)
        self.parent = double(self.parent)
        for name in self._cols:
            setattr(self, name, double(getattr(self, name)))
        if self.alive is not None:
            self.alive = np.concatenate([self.alive, np.ones_like(self.alive)])
        if self.kd is not None:
            self.kd = (double(self.kd[0]), self.kd[1])

    def add(self, x: Any, parent: int, edge: Any = None, **columns: Any) -> int:
        """Append a node (key ``x``, column values ``columns``, edge payload ``edge``) below
        ``parent``; returns its index."""
        if self.n == len(self.X):
            self._grow()
        n = self.n
        self.X[n] = x
        self.parent[n] = parent
        for name, v in columns.items():
            getattr(self, name)[n] = v
        if self.edge is not None:
            self.edge.append([] if edge is None else edge)
        self.n = n + 1
        return n

    def nearest(self, x: Any) -> int:
        """Index of the live node nearest ``x`` (squared Euclidean distance in the key)."""
        nn = _NATIVE_NN[0] if _NATIVE_NN else _native_nearest()
        if nn is not None:
            return int(nn(self.X, self.n, x, self.alive if self.n_dead else None, self.kd))
        d = self.X[:self.n] - x
        d2 = np.einsum("ij,ij->i", d, d)
        if self.n_dead and self.alive is not None:
            d2[~self.alive[:self.n]] = np.inf
        return int(np.argmin(d2))

    def live_keys(self) -> np.ndarray:
        """Key coordinates of the live nodes."""
        if not self.n_dead or self.alive is None:
            return self.X[:self.n]
        return self.X[:self.n][self.alive[:self.n]]

    def kill(self, i: int) -> int:
        """Delete node ``i`` and its subtree (children have larger indices); returns how many
        nodes died."""
        if self.alive is None:
            self.alive = np.ones(len(self.X), dtype=bool)
        dead = 0
        alive, parent = self.alive, self.parent
        for k in range(i, self.n):
            if alive[k] and (k == i or not alive[parent[k]]):
                alive[k] = False
                dead += 1
        self.n_dead += dead
        return dead

    def indices(self, i: int) -> list[int]:
        """Node indices from the root to node ``i``."""
        out: list[int] = []
        parent = self.parent
        while i >= 0:
            out.append(int(i))
            i = int(parent[i])
        return out[::-1]

    def branch(self, i: int, column: str | None = None) -> list[np.ndarray]:
        """Copies of the key from the root to node ``i``, each edge's intermediate configurations
        (payload, when the tree keeps edges) before its end node; or copies of ``column`` at the
        nodes only."""
        A = self.X if column is None else getattr(self, column)
        out: list[np.ndarray] = []
        edge = self.edge if column is None else None
        for k in self.indices(i):
            if edge is not None:
                out.extend(x.copy() for x in edge[k])
            out.append(A[k].copy())
        return out


def joined_path(ta: Tree, i: int, tb: Tree, j: int, a_is_start: bool) -> list[np.ndarray]:
    """The path of two trees that met, from the start to the goal: root of ``ta`` → node ``i``, then
    node ``j`` of ``tb`` → its root (``i`` and ``j`` hold the same configuration, kept once);
    ``a_is_start``: ``ta`` grew from the start (else the path is reversed)."""
    pa, pb = ta.branch(i), tb.branch(j)
    path = pa + pb[::-1][1:]
    return path if a_is_start else path[::-1]
