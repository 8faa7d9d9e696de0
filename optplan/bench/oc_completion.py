"""Paired benchmark of OC-RRT's manifold completion: the compiled branch kernel (CasADi → C) against
the Python path of the analytic IK, inside the same OC-RRT-Connect planner, same collision checker,
same seeds, on the four PR2 scenes.

``python -m optplan.bench.oc_completion [--trials 10] [--time-limit 10]`` prints, per scene and
completion path: success rate, median planning time (CPU seconds) and nodes of the successful
queries, and the planning time per completion call, with the speed-up of the compiled path.
Needs ``example-robot-data``.
"""
from __future__ import annotations

import argparse
import statistics

import numpy as np

__all__ = ["run"]


def run(trials: int = 10, time_limit: float = 10.0, seed: int = 0, scenes=None) -> list[dict]:
    from ..planners.oc_rrt import OCRRT, OCRRTOptions
    from ..planners.orientation import OrientationManifold
    from .oc_rrt import SCENES, setup_scene

    rows = []
    for sc in scenes or SCENES:
        s = setup_scene(sc, ["oc_rrt_connect"])
        for path, mf in (("compiled", s["manifold"]), ("python", OrientationManifold(s["constraint"], compiled=False))):
            pl = OCRRT(s["robot"], s["scene"], s["constraint"], OCRRTOptions(connect=True), checker=s["checker"],
                       manifold=mf)
            runs = []
            for i in range(trials):
                sd = int(np.random.SeedSequence(seed, spawn_key=(i,)).generate_state(1)[0] % (2 ** 31))
                r = pl.plan(s["q_start"], s["q_goal"], time_limit=time_limit, seed=sd, clock="cpu")
                runs.append((r.success, r.stats["cpu_time_s"], r.stats["nodes"], r.stats["ik_completions"]))
            ok = [x for x in runs if x[0]]
            rows.append({"scene": sc, "completion": path, "trials": trials, "success_rate": len(ok) / trials,
                         "median_time_s": statistics.median([x[1] for x in ok]) if ok else None,
                         "median_nodes": statistics.median([x[2] for x in ok]) if ok else None,
                         "us_per_completion": 1e6 * sum(x[1] for x in runs) / max(1, sum(x[3] for x in runs))})
    return rows


def main(argv=None) -> int:
    from ..model.example_robots import example_robots_available

    p = argparse.ArgumentParser(description="OC-RRT-Connect: compiled vs Python manifold completion (paired)")
    p.add_argument("--trials", type=int, default=10)
    p.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds per query")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    if not example_robots_available():
        print("needs the example-robot-data package: pip install \"optplan[robots]\"")
        return 2
    rows = run(a.trials, a.time_limit, a.seed)
    print(f"{'scene':16s} {'completion':10s} {'success':>7s} {'median t [s]':>12s} {'nodes':>7s} {'µs/completion':>13s}")
    fm = lambda v, f: "/" if v is None else format(v, f)  # noqa: E731
    for r in rows:
        print(f"{r['scene']:16s} {r['completion']:10s} {r['success_rate']:7.2f} {fm(r['median_time_s'], '12.4f')} "
              f"{fm(r['median_nodes'], '7.1f')} {r['us_per_completion']:13.1f}")
    for sc in dict.fromkeys(r["scene"] for r in rows):
        c, py = (next(r for r in rows if r["scene"] == sc and r["completion"] == k) for k in ("compiled", "python"))
        if c["median_time_s"] and py["median_time_s"]:
            print(f"{sc}: compiled path {py['median_time_s'] / c['median_time_s']:.1f}x faster (median CPU time)")
    print("planning time per completion includes collision checks and tree bookkeeping (CPU seconds)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
