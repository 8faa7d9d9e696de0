"""The trees' nearest-neighbour search: the native k-d index (:func:`optplan.planners.kernel.extend.kd_index`) against
the native linear scan and SciPy's ``cKDTree`` (balanced, built once over all rows), on the same keys and queries.

``python -m optplan.bench.nearest_index [--rows 5000,30000] [--queries 2000] [--seed 0]``

Key sets of 6-D rows (a task tree's key: position [m], roll, pitch, yaw [rad]): ``gauss`` (independent normal rows)
and ``rrt`` (a tree grown by steps of 0.05 from random nodes toward uniform samples in [-3, 3]^6, as a planner's
tree grows). Queries ``near`` (a row plus noise of 0.01) and ``far`` (uniform in the sampling box; four times wider
for ``gauss``): a planner's samples mostly lie far from its trees. Per case: µs per query of the index and of the
scan, both through :func:`~optplan.planners.kernel.extend.nearest` (the ctypes call included), timed in alternating
blocks on the same queries, their ratio, and ``cKDTree.query`` one query at a time; then the same inside one native
call for all queries (:func:`~optplan.planners.kernel.extend.nearest_batch`: the cost a search in C pays per query,
no ctypes call), beside ``cKDTree.query`` of all queries at once. Every answer of the index is checked against the
scan's (the first row among equal distances): a mismatch raises.
"""
from __future__ import annotations

import argparse
import functools
import time
from typing import Any

import numpy as np

__all__ = ["rrt_keys", "nearest_costs", "main"]


def rrt_keys(n: int, rng: np.random.Generator, step: float = 0.05, box: float = 3.0) -> np.ndarray:
    """``n`` 6-D keys of a tree grown from the origin: each row one ``step`` from a random earlier row toward a
    uniform sample of [-box, box]^6."""
    X = np.zeros((n, 6))
    for i in range(1, n):
        s = rng.uniform(-box, box, 6)
        j = int(rng.integers(i))
        d = s - X[j]
        X[i] = X[j] + step * d / np.linalg.norm(d)
    return X


def _kd(X: np.ndarray, n: int, idx: Any, q: np.ndarray) -> int:
    from ..planners.kernel.extend import nearest

    return nearest(X, n, q, None, idx)


def _scan(X: np.ndarray, n: int, q: np.ndarray) -> int:
    from ..planners.kernel.extend import nearest

    return nearest(X, n, q)


def _timed(f: Any, Q: np.ndarray, blocks: int = 4) -> tuple[float, list[int]]:
    out: list[int] = []
    t = 0.0
    for B in np.array_split(Q, blocks):
        c = time.perf_counter()
        out.extend(f(q) for q in B)
        t += time.perf_counter() - c
    return t / len(Q) * 1e6, out


def _native_costs(X: np.ndarray, rows: int, idx: Any, Q: np.ndarray, tree: Any, reps: int = 3) -> tuple[float, float, float]:
    """µs per query inside one native call for all queries (:func:`~optplan.planners.kernel.extend.nearest_batch`):
    the index and the scan (the best of ``reps`` alternating runs; their answers compared), and cKDTree's own batch
    ``query`` of all queries at once."""
    from ..planners.kernel.extend import nearest_batch

    best = [np.inf, np.inf, np.inf]
    for _ in range(reps):
        t = time.perf_counter()
        a = nearest_batch(X, rows, Q, None, idx)
        best[0] = min(best[0], time.perf_counter() - t)
        t = time.perf_counter()
        b = nearest_batch(X, rows, Q)
        best[1] = min(best[1], time.perf_counter() - t)
        t = time.perf_counter()
        tree.query(Q, k=1)
        best[2] = min(best[2], time.perf_counter() - t)
        if not np.array_equal(a, b):
            raise AssertionError("nearest_index: the k-d index and the scan disagree (native batch)")
    return tuple(v / len(Q) * 1e6 for v in best)  # type: ignore[return-value]


def nearest_costs(rows: int, n_queries: int, seed: int = 0) -> list[dict[str, Any]]:
    """One row per (key set, query kind) with ``rows`` keys and ``n_queries`` queries: µs per query of the index
    (``kd_us``), the scan (``scan_us``) and cKDTree (``ckdtree_us``)."""
    from scipy.spatial import cKDTree

    from ..planners.kernel.extend import kd_index, nearest

    rng = np.random.default_rng(seed)
    out = []
    for kind in ("gauss", "rrt"):
        X = rng.normal(size=(rows, 6)) if kind == "gauss" else rrt_keys(rows, rng)
        idx = kd_index(rows, 6)
        tree = cKDTree(X, leafsize=16)
        for qk in ("near", "far"):
            Q = X[rng.integers(rows, size=n_queries)] + 0.01 * rng.normal(size=(n_queries, 6)) if qk == "near" \
                else rng.uniform(-3, 3, (n_queries, 6)) * (4.0 if kind == "gauss" else 1.0)
            nearest(X, rows, Q[0], None, idx)                       # the index takes its rows
            kd_us = scan_us = 0.0
            for half in np.array_split(np.arange(n_queries), 2):  # alternating which runs first
                runs = [("kd", functools.partial(_kd, X, rows, idx)), ("scan", functools.partial(_scan, X, rows))]
                got = {}
                for name, f in (runs if half[0] == 0 else runs[::-1]):
                    us, ans = _timed(f, Q[half])
                    got[name] = ans
                    if name == "kd":
                        kd_us += us * len(half) / n_queries
                    else:
                        scan_us += us * len(half) / n_queries
                if got["kd"] != got["scan"]:
                    raise AssertionError(f"nearest_index: the k-d index and the scan disagree ({kind}, {qk})")
            ck_us, _ = _timed(functools.partial(tree.query, k=1), Q[:min(n_queries, 500)])
            c_kd, c_scan, c_ck = _native_costs(X, rows, idx, Q, tree)
            out.append({"rows": rows, "keys": kind, "queries": qk, "kd_us": kd_us, "scan_us": scan_us,
                        "ckdtree_us": ck_us, "kd_c_us": c_kd, "scan_c_us": c_scan, "ckdtree_batch_us": c_ck})
    return out


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.nearest_index", description=__doc__.splitlines()[0])
    ap.add_argument("--rows", default="5000,30000", help="key rows, comma-separated")
    ap.add_argument("--queries", type=int, default=2000, help="queries per case")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    rows = []
    print("| rows | keys | queries | k-d index µs | scan µs | index / scan | cKDTree µs (one query) | in C: index µs | "
          "in C: scan µs | in C: index / scan | cKDTree µs (all queries in one call) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for n in (int(v) for v in a.rows.split(",")):
        for r in nearest_costs(n, a.queries, a.seed):
            rows.append(r)
            print(f"| {r['rows']} | {r['keys']} | {r['queries']} | {r['kd_us']:.1f} | {r['scan_us']:.1f} | "
                  f"{r['kd_us'] / r['scan_us']:.2f} | {r['ckdtree_us']:.1f} | {r['kd_c_us']:.2f} | {r['scan_c_us']:.2f} | "
                  f"{r['kd_c_us'] / r['scan_c_us']:.2f} | {r['ckdtree_batch_us']:.2f} |", flush=True)
    return rows


if __name__ == "__main__":
    main()
