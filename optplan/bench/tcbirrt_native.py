"""TCBiRRT's extension step and nearest neighbour in native code against the Python ones, paired: whole
queries on the same trials and seeds with ``extension="native"`` (and the trees' native nearest-neighbour
scan) and ``extension="python"`` (and numpy's), alternating which runs first, CPU clock. Both use the
native collision kernel (``validity_kernel="native"``), today's default.

``python -m optplan.bench.tcbirrt_native --scene hard_bay,hard_window,ssps_scene1 --trials 0,1,2``

Per query: status, CPU seconds, iterations, CPU per iteration; per scene the medians, the paired ratio
python / native of the CPU per iteration, and in how many pairs the two ran the same search (same
iteration and node counts: they should, up to rounding in the last bits of the pose interpolation).
"""
from __future__ import annotations

import argparse
import contextlib
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

__all__ = ["paired_queries", "python_nearest", "main"]

KINDS = ("native", "python")


@contextlib.contextmanager
def python_nearest() -> Iterator[None]:
    """Inside: :meth:`optplan.planners.tree.Tree.nearest` uses numpy's search (the native scan off)."""
    from ..planners import tree

    tree._native_nearest()
    saved = list(tree._NATIVE_NN)
    tree._NATIVE_NN[:] = [None]
    try:
        yield
    finally:
        tree._NATIVE_NN[:] = saved


def paired_queries(scenes: list[str], trials: list[int], planner: str = "tcbirrt:variant=improved", *,
                   seed: int = 0, time_limit: float = 10.0, robot_name: str = "tcbirrt_dual_arm") -> list[dict[str, Any]]:
    """Each trial of each scene planned both ways (native first on even trials, Python first on odd ones),
    same trial seed. One row per query."""
    from .tcbirrt import _W, _worker_setup, expand_scenes

    specs = {k: f"{planner}:extension={k}" for k in KINDS}
    scenes = expand_scenes(scenes)
    _worker_setup(robot_name, scenes, list(specs.values()))
    rows = []
    for sc in scenes:
        w = _W[sc]
        for i in trials:
            t = w["gen"].generate(int(i), seed)
            for kind in (KINDS if i % 2 == 0 else KINDS[::-1]):
                pl = w["planners"][specs[kind]]
                with python_nearest() if kind == "python" else contextlib.nullcontext():
                    c0 = time.process_time()
                    res = pl.plan(t.q_start, t.q_goal, time_limit=time_limit, seed=t.seed, clock="cpu")
                    cpu = time.process_time() - c0
                it = int(res.stats.get("iterations") or 0)
                rows.append({"scene": sc, "trial": int(i), "kind": kind, "status": res.status.value, "cpu_s": cpu,
                             "iterations": it, "cpu_per_iteration_ms": 1e3 * cpu / max(it, 1),
                             "nodes": res.stats.get("nodes"), "native": getattr(pl, "_ext", None) is not None})
    return rows


def summary(rows: list[dict[str, Any]]) -> str:
    """Per scene: success, median CPU and CPU per iteration of each kind, the paired ratio, same searches."""
    lines = [f"{'scene':22s} {'kind':7s} {'success':>8s} {'median CPU s':>13s} {'median ms/iter':>15s}"]
    for sc in dict.fromkeys(r["scene"] for r in rows):
        per = {}
        for kind in KINDS:
            rr = [r for r in rows if r["scene"] == sc and r["kind"] == kind]
            per[kind] = rr
            succ = np.mean([r["status"] == "exact" for r in rr])
            lines.append(f"{sc:22s} {kind:7s} {succ:8.2f} {np.median([r['cpu_s'] for r in rr]):13.3f} "
                         f"{np.median([r['cpu_per_iteration_ms'] for r in rr]):15.3f}")
        ratio = [p["cpu_per_iteration_ms"] / n["cpu_per_iteration_ms"] for n, p in zip(per["native"], per["python"])]
        same = sum(n["iterations"] == p["iterations"] and n["nodes"] == p["nodes"] for n, p in zip(per["native"], per["python"]))
        lines.append(f"{sc:22s} paired python/native CPU per iteration: median {np.median(ratio):.2f}x "
                     f"(min {min(ratio):.2f}, max {max(ratio):.2f}); same search in {same}/{len(ratio)}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.tcbirrt_native",
                                 description="TCBiRRT's native extension step vs the Python one: paired queries")
    ap.add_argument("--scene", default="hard_bay,hard_window,ssps_scene1", help="comma-separated scenes")
    ap.add_argument("--trials", default="0,1,2", help="comma-separated trial indices [index]")
    ap.add_argument("--planners", default="tcbirrt:variant=improved", help="one planner spec")
    ap.add_argument("--seed", type=int, default=0, help="trial seed")
    ap.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds per query [s]")
    a = ap.parse_args(argv)
    from .tcbirrt import expand_scenes

    rows = paired_queries(expand_scenes(a.scene.split(",")), [int(x) for x in a.trials.split(",") if x.strip()],
                          a.planners, seed=a.seed, time_limit=a.time_limit)
    for r in rows:
        print(f"{r['scene']} trial {r['trial']} {r['kind']:6s}: {r['status']}, {r['cpu_s']:.3f} s CPU, "
              f"{r['iterations']} iterations, {r['nodes']} nodes, {r['cpu_per_iteration_ms']:.3f} ms/iteration"
              + ("" if r["native"] or r["kind"] == "python" else " (native extension unavailable: Python ran)"))
    print(summary(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
