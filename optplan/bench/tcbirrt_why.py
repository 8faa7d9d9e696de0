"""Why a TCBiRRT query is slow: the search's own counters per query, and per scene the figures that tell a
search that cannot meet (IK branches, regrasps) from one that is merely slow per iteration.

``python -m optplan.bench.tcbirrt_why --scene hard_truss --trials 0-24``

Per query (the benchmark's trials and planner, CPU clock): status, CPU seconds, iterations, regrasp
attempts / failures / CPU seconds, branch and frontier grafts (attempts, successes) and the regrasp
segments of the path. Per scene: success, median and mean CPU, the share of the CPU in regrasps, how many
paths need a regrasp (the trees met on different IK branches), and how many queries that ran past
``graft_after`` ended on a frontier-graft iteration (a multiple of ``frontier_interval`` after it: the
trees joined only through a re-grasp at their frontier).
"""
from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

__all__ = ["query_rows", "scene_summary", "main"]


def query_rows(scenes: list[str], trials: list[int], planner: str = "tcbirrt:variant=improved", *, seed: int = 0,
               time_limit: float = 10.0, robot_name: str = "tcbirrt_dual_arm") -> list[dict[str, Any]]:
    """Each trial of each scene planned once (trial seed ``seed``, ``time_limit`` CPU seconds [s]); one row
    of counters per query."""
    from .tcbirrt import _W, _worker_setup, expand_scenes

    scenes = expand_scenes(scenes)
    _worker_setup(robot_name, scenes, [planner])
    rows = []
    for sc in scenes:
        w = _W[sc]
        pl = w["planners"][planner]
        for i in trials:
            t = w["gen"].generate(int(i), seed)
            c0 = time.process_time()
            res = pl.plan(t.q_start, t.q_goal, time_limit=time_limit, seed=t.seed, clock="cpu")
            cpu = time.process_time() - c0
            s = res.stats
            rows.append({"scene": sc, "trial": int(i), "status": res.status.value, "cpu_s": cpu,
                         "iterations": int(s.get("iterations") or 0), "regrasp_attempts": int(s.get("regrasp_attempts") or 0),
                         "regrasp_failures": int(s.get("regrasp_failures") or 0),
                         "regrasp_s": float(s.get("regrasp_time_s") or 0.0),
                         "graft_attempts": int(s.get("graft_attempts") or 0), "grafts": int(s.get("grafts") or 0),
                         "frontier_attempts": int(s.get("frontier_attempts") or 0),
                         "frontier_grafts": int(s.get("frontier_grafts") or 0),
                         "n_regrasp": int(res.n_regrasp) if res.success else 0,
                         "graft_after": int(getattr(pl.options, "graft_after", 0)),
                         "frontier_interval": int(getattr(pl.options, "frontier_interval", 0)),
                         "frontier_on": bool(getattr(pl.options, "frontier_grafts", 0))})
    return rows


def scene_summary(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Figures of one scene's rows: ``n``, ``success``, ``median_cpu_s``, ``mean_cpu_s``, ``regrasp_share``
    (regrasp CPU / all CPU), ``with_regrasp`` (successful paths with a regrasp segment), ``past_graft_after``
    (queries that ran past ``graft_after``) and ``at_frontier_graft`` (of those, the successes on a
    frontier-graft iteration)."""
    ok = [r for r in rows if r["status"] == "exact"]
    cpu = np.array([r["cpu_s"] for r in rows], float)
    past = [r for r in rows if r["frontier_on"] and r["iterations"] > r["graft_after"]]
    at = [r for r in past if r["status"] == "exact" and r["frontier_interval"]
          and (r["iterations"] - r["graft_after"]) % r["frontier_interval"] == 0]
    return {"n": len(rows), "success": len(ok), "median_cpu_s": float(np.median(cpu)), "mean_cpu_s": float(cpu.mean()),
            "regrasp_share": float(sum(r["regrasp_s"] for r in rows) / max(cpu.sum(), 1e-12)),
            "with_regrasp": sum(r["n_regrasp"] > 0 for r in ok), "past_graft_after": len(past), "at_frontier_graft": len(at),
            "graft_attempts": sum(r["graft_attempts"] for r in rows), "grafts": sum(r["grafts"] for r in rows),
            "regrasp_attempts": sum(r["regrasp_attempts"] for r in rows),
            "regrasp_failures": sum(r["regrasp_failures"] for r in rows)}


def _trials(text: str) -> list[int]:
    out: list[int] = []
    for part in (p.strip() for p in text.split(",") if p.strip()):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b) + 1) if b else [int(a)])
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.tcbirrt_why",
                                 description="TCBiRRT's counters per query and why a scene is slow")
    ap.add_argument("--scene", default="hard_truss", help="comma-separated scenes")
    ap.add_argument("--trials", default="0-24", help="trial indices: comma-separated, ranges a-b [index]")
    ap.add_argument("--planners", default="tcbirrt:variant=improved", help="one planner spec")
    ap.add_argument("--seed", type=int, default=0, help="trial seed")
    ap.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds per query [s]")
    a = ap.parse_args(argv)
    rows = query_rows([s for s in a.scene.split(",") if s.strip()], _trials(a.trials), a.planners, seed=a.seed,
                      time_limit=a.time_limit)
    for r in rows:
        print(f"{r['scene']} trial {r['trial']}: {r['status']}, {r['cpu_s']:.3f} s CPU, {r['iterations']} iterations, "
              f"regrasps {r['regrasp_attempts']} ({r['regrasp_failures']} failed, {r['regrasp_s']:.3f} s), grafts "
              f"{r['grafts']}/{r['graft_attempts']}, frontier {r['frontier_grafts']}/{r['frontier_attempts']}, "
              f"regrasp segments {r['n_regrasp']}")
    for sc in dict.fromkeys(r["scene"] for r in rows):
        s = scene_summary([r for r in rows if r["scene"] == sc])
        print(f"{sc}: {s['success']}/{s['n']} solved, median {s['median_cpu_s']:.3f} s, mean {s['mean_cpu_s']:.3f} s CPU; "
              f"regrasps {s['regrasp_share']:.0%} of the CPU ({s['regrasp_attempts']} attempts, {s['regrasp_failures']} "
              f"failed); {s['with_regrasp']}/{s['success']} paths need a regrasp; {s['at_frontier_graft']} of the "
              f"{s['past_graft_after']} queries past graft_after ended on a frontier-graft iteration; branch grafts "
              f"{s['grafts']}/{s['graft_attempts']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
