"""TCBiRRT's native extension step and nearest-neighbour scan (optplan.planners.kernel.extend) against
the Python code they replace: numpy's brute-force search, interpolate_task, the compiled IK called from
Python, and the validity checker's edge checks."""
from __future__ import annotations

import numpy as np
import pytest

from optplan.planners.kernel.extend import nearest, nearest_available

pytestmark = pytest.mark.skipif(not nearest_available(), reason="no C compiler: the native extension is not built")


def _brute(X, n, x, alive=None):
    d = X[:n] - x
    d2 = np.einsum("ij,ij->i", d, d)
    if alive is not None:
        d2[~alive[:n]] = np.inf
    return int(np.argmin(d2))


def test_native_nearest_matches_brute_force_with_dead_nodes_and_ties():
    rng = np.random.default_rng(11)
    for dim in (3, 6, 14):
        X = rng.normal(size=(700, dim))
        X[400:450] = X[300:350]                 # exact duplicates: the first index wins, as argmin's
        alive = rng.random(700) > 0.3
        for _ in range(200):
            n = int(rng.integers(1, 701))
            x = X[int(rng.integers(n))] if rng.random() < 0.3 else rng.normal(size=dim)
            assert nearest(X, n, x) == _brute(X, n, x)
            if alive[:n].any():
                assert nearest(X, n, x, alive) == _brute(X, n, x, alive)


def test_native_nearest_bad_input():
    X = np.zeros((5, 6))
    with pytest.raises(ValueError, match="rows of 3 values"):
        nearest(X, 5, np.zeros(3))
    with pytest.raises(ValueError, match="n = 9"):
        nearest(X, 9, np.zeros(6))
    with pytest.raises(ValueError, match="C-contiguous float64"):
        nearest(np.zeros((5, 6), np.float32), 5, np.zeros(6))


def test_tree_uses_the_native_scan_with_the_same_answers():
    from optplan.planners.tree import Tree

    rng = np.random.default_rng(3)
    t = Tree(rng.normal(size=6), cap=4)
    for _ in range(300):
        t.add(rng.normal(size=6), int(rng.integers(t.n)))
    t.kill(57)
    for _ in range(100):
        x = rng.normal(size=6)
        assert t.nearest(x) == _brute(t.X, t.n, x, t.alive)
