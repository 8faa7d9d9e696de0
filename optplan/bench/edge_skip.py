"""A found path's edge re-checks with safe steps against checking every point, paired on the same edges.

``python -m optplan.bench.edge_skip --scene ssps,suite --trials 0-4``

The improved TCBiRRT plans the given trials (10 s CPU each); every edge its ``verify_path`` re-checks (uniform
points, :meth:`~optplan.planners.validity.ValidityChecker.uniform_edge_is_valid`) and every found regrasp
motion's re-check (Jacobian-spaced points, ``edge_is_valid(..., expect_free=True)``) is recorded with its mode,
still-object pose and active pairs. Then each recorded edge is checked both ways in alternating passes on the
CPU clock: every point (``kernel_edge_first_invalid``, one native call) and with safe steps
(``kernel_edge_first_invalid_skip``). Printed per scene and kind: edges, points, points checked with safe
steps, CPU of both ways (best pass) and their ratio; the run stops with an error if any edge gets another first
point in collision.
"""
from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

__all__ = ["record_edges", "paired_costs", "main"]


def record_edges(scene: str, trials: list[int], seed: int = 0, time_limit: float = 10.0) -> list[tuple[Any, ...]]:
    """The re-checked edges of the improved TCBiRRT's queries on ``trials`` of ``scene``: tuples (kind
    ``"verify"`` / ``"regrasp"``, native backend, a, b, fractions, mode, object pose, active mask copy)."""
    from ..planners.validity import ValidityChecker
    from .tcbirrt import _W, _worker_setup, expand_scenes

    planner = "tcbirrt:variant=improved"
    rec: list[tuple[Any, ...]] = []
    uniform, edge = ValidityChecker.uniform_edge_is_valid, ValidityChecker.edge_is_valid

    def rec_uniform(self: Any, a: Any, b: Any, tol: float, weights: Any, mode: str = "held", object_pose: Any = None) -> bool:
        m = "free" if mode == "held" and self.object is None else mode
        a_, b_ = np.array(a, float), np.array(b, float)
        n = max(1, int(np.ceil(float(np.max(weights @ np.abs(b_ - a_))) / tol)))
        if n >= 2 and self._native is not None:
            rec.append(("verify", self._native, a_, b_, np.arange(1, n) / n, m, object_pose, self._native.masks[m].copy()))
        return uniform(self, a, b, tol, weights, mode, object_pose)

    def rec_edge(self: Any, a: Any, b: Any, tolerance: float, mode: str = "held", object_pose: Any = None,
                 check_end: bool = False, expect_free: bool = False) -> bool:
        if expect_free and self._native is not None:
            m = "free" if mode == "held" and self.object is None else mode
            a_, b_ = np.array(a, float), np.array(b, float)
            ts = self.edge_checkpoints(a_, b_, tolerance, mode)
            if len(ts):
                rec.append(("regrasp", self._native, a_, b_, ts, m, object_pose, self._native.masks[m].copy()))
        return edge(self, a, b, tolerance, mode, object_pose, check_end, expect_free)

    (sc,) = expand_scenes([scene])
    _worker_setup("tcbirrt_dual_arm", [sc], [planner])
    w = _W[sc]
    ValidityChecker.uniform_edge_is_valid = rec_uniform   # type: ignore[method-assign,assignment]
    ValidityChecker.edge_is_valid = rec_edge              # type: ignore[method-assign]
    try:
        for i in trials:
            t = w["gen"].generate(int(i), seed)
            w["planners"][planner].plan(t.q_start, t.q_goal, time_limit=time_limit, seed=t.seed, clock="cpu")
    finally:
        ValidityChecker.uniform_edge_is_valid = uniform   # type: ignore[method-assign]
        ValidityChecker.edge_is_valid = edge              # type: ignore[method-assign]
    return rec


def paired_costs(rec: list[tuple[Any, ...]], repeats: int = 3) -> dict[str, dict[str, float]]:
    """Per kind: edges, points, points checked with safe steps, best-pass CPU [s] of every point and of safe steps.
    Raises ``AssertionError`` if an edge gets another first point in collision."""
    out: dict[str, dict[str, float]] = {}
    best: dict[str, list[float]] = {}
    for rep in range(repeats):
        tot: dict[str, list[float]] = {}
        for kind, nv, a, b, f, m, op, mask in rec:
            K, ov = nv.kernel, nv._override(m, op)
            t0 = time.process_time()
            k0 = K.edge_first_invalid(a, b, f, mask, ov)
            t1 = time.process_time()
            k1, c = K.edge_first_invalid_skip(a, b, f, mask, ov)
            t2 = time.process_time()
            assert k0 == k1, f"{kind} edge: first point in collision {k1} with safe steps, {k0} checking every point"
            x = tot.setdefault(kind, [0.0, 0.0])
            x[0] += t1 - t0
            x[1] += t2 - t1
            if rep == 0:
                row = out.setdefault(kind, {"edges": 0, "points": 0, "checked": 0})
                row["edges"] += 1
                row["points"] += len(f) if k0 < 0 else k0 + 1
                row["checked"] += c
        for kind, (x0, x1) in tot.items():
            b_ = best.setdefault(kind, [np.inf, np.inf])
            b_[0], b_[1] = min(b_[0], x0), min(b_[1], x1)
    for kind, row in out.items():
        row["cpu_every_s"], row["cpu_skip_s"] = best[kind]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.edge_skip",
                                 description="re-checked edges with safe steps vs every point, paired")
    ap.add_argument("--scene", default="ssps", help="comma-separated scenes (names, 'ssps', 'suite')")
    ap.add_argument("--trials", default="0-4", help="trial indices: 'a-b' or comma-separated")
    ap.add_argument("--seed", type=int, default=0, help="trial seed")
    ap.add_argument("--repeats", type=int, default=3, help="alternating passes (best taken)")
    a = ap.parse_args(argv)
    from .tcbirrt import expand_scenes

    if "-" in a.trials:
        lo, hi = (int(x) for x in a.trials.split("-"))
        trials = list(range(lo, hi + 1))
    else:
        trials = [int(x) for x in a.trials.split(",") if x.strip()]
    print(f"{'scene':22s} {'kind':8s} {'edges':>6s} {'points':>8s} {'checked':>8s} {'share':>6s} "
          f"{'every [ms]':>10s} {'skip [ms]':>10s} {'ratio':>6s}")
    for sc in expand_scenes(a.scene.split(",")):
        for kind, r in sorted(paired_costs(record_edges(sc, trials, a.seed), a.repeats).items(), reverse=True):
            print(f"{sc:22s} {kind:8s} {r['edges']:6.0f} {r['points']:8.0f} {r['checked']:8.0f} "
                  f"{r['checked'] / max(r['points'], 1):6.2f} {1e3 * r['cpu_every_s']:10.1f} {1e3 * r['cpu_skip_s']:10.1f} "
                  f"{r['cpu_skip_s'] / max(r['cpu_every_s'], 1e-12):6.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
