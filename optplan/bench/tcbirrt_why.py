"""Why a TCBiRRT query is slow: the search's own counters per query, and per scene the figures that tell a
search that cannot meet (IK branches, regrasps) from one that is merely slow per iteration.

``python -m optplan.bench.tcbirrt_why --scene hard_truss --trials 0-24``

``--jsonl FILE`` appends one JSON line per query (the counters below and the search's size: nodes, IK iterations,
collision checks, joint-path length); ``--compare A B`` prints two such files paired per scene and trial (run
one per code tree, e.g. main extracted with ``git archive`` on ``PYTHONPATH``): success, median CPU and
iterations, CPU per iteration and how many pairs ran the same search. ``--regrasp-calls`` prints every native
RRT-Connect call of a regrasp or graft: status, iterations, nodes of the start's and the goal's tree, the
longest stall of a tree, CPU seconds and the caller.

Per query (the benchmark's trials and planner, CPU clock): status, CPU seconds, iterations, regrasp
attempts / failures / CPU seconds, branch and frontier grafts (attempts, successes) and the regrasp
segments of the path. Per scene: success, median and mean CPU, the share of the CPU in regrasps, how many
paths need a regrasp (the trees met on different IK branches), and how many queries that ran past
``graft_after`` ended on a frontier-graft iteration (a multiple of ``frontier_interval`` after it: the
trees joined only through a re-grasp at their frontier).
"""
from __future__ import annotations

import argparse
import json
import time
import traceback
from typing import Any

import numpy as np

__all__ = ["query_rows", "scene_summary", "main"]


def query_rows(scenes: list[str], trials: list[int], planner: str = "tcbirrt:variant=improved", *, seed: int = 0,
               time_limit: float = 10.0, robot_name: str = "tcbirrt_dual_arm",
               calls: list[dict[str, Any]] | None = None) -> list[dict[str, Any]]:
    """Each trial of each scene planned once (trial seed ``seed``, ``time_limit`` CPU seconds [s]); one row
    of counters per query (with ``calls``, the list :func:`log_regrasp_calls` fills: the query's calls as
    ``regrasp_calls``)."""
    from .tcbirrt import _W, _worker_setup, expand_scenes

    scenes = expand_scenes(scenes)
    _worker_setup(robot_name, scenes, [planner])
    rows = []
    for sc in scenes:
        w = _W[sc]
        pl = w["planners"][planner]
        for i in trials:
            t = w["gen"].generate(int(i), seed)
            n0 = len(calls) if calls is not None else 0
            c0 = time.process_time()
            res = pl.plan(t.q_start, t.q_goal, time_limit=time_limit, seed=t.seed, clock="cpu")
            cpu = time.process_time() - c0
            s = res.stats
            P = np.asarray(res.path)
            length = float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum()) if res.success and len(P) > 1 else None
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
                         "frontier_on": bool(getattr(pl.options, "frontier_grafts", 0)),
                         "nodes": int(s.get("nodes") or 0), "ik_iterations": int(s.get("ik_iterations") or 0),
                         "collision_checks": int(s.get("collision_checks") or 0),
                         "graft_repeats_skipped": int(s.get("graft_repeats_skipped") or 0),
                         "regrasp_stalled": int(s.get("regrasp_stalled") or 0), "joint_length": length})
            if calls is not None:
                rows[-1]["regrasp_calls"] = calls[n0:]
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


def compare(a: list[dict[str, Any]], b: list[dict[str, Any]]) -> str:
    """Rows of two runs (``--jsonl``) paired by scene and trial: a Markdown table per scene — success, median CPU s
    and iterations of each, CPU per iteration a / b (total CPU / total iterations), the pairs with the same search
    (iterations, nodes, IK iterations), the median joint-path length b / a over the pairs both solve and the CPU
    of those pairs."""
    A = {(r["scene"], r["trial"]): r for r in a}
    lines = ["| scene | a: solved, median CPU s, median iterations | b | CPU per iteration a / b | same search | "
             "path length b / a (median) | both solved: CPU s a → b |", "|---|---|---|---|---|---|---|"]
    for sc in dict.fromkeys(r["scene"] for r in b):
        pairs = [(A[(sc, r["trial"])], r) for r in b if r["scene"] == sc and (sc, r["trial"]) in A]
        if not pairs:
            continue
        ra, rb = [x for x, _ in pairs], [y for _, y in pairs]
        both = [(x, y) for x, y in pairs if x["status"] == y["status"] == "exact"]
        same = sum(all(x[k] == y[k] for k in ("iterations", "nodes", "ik_iterations")) for x, y in pairs)
        per = [sum(r["cpu_s"] for r in rs) / max(1, sum(r["iterations"] for r in rs)) for rs in (ra, rb)]
        ratio = np.median([y["joint_length"] / x["joint_length"] for x, y in both]) if both else float("nan")

        def cell(rs: list[dict[str, Any]]) -> str:
            return (f"{sum(r['status'] == 'exact' for r in rs)}/{len(rs)}, {np.median([r['cpu_s'] for r in rs]):.3f}, "
                    f"{np.median([r['iterations'] for r in rs]):.0f}")

        lines.append(f"| {sc} | {cell(ra)} | {cell(rb)} | {per[0] / max(per[1], 1e-12):.2f}× | {same}/{len(pairs)} | "
                     f"{ratio:.3f} | {sum(x['cpu_s'] for x, _ in both):.2f} → {sum(y['cpu_s'] for _, y in both):.2f} |")
    return "\n".join(lines)


def log_regrasp_calls() -> list[dict[str, Any]]:
    """Record every native RRT-Connect call from now on (the list returned grows): status, iterations, tree
    nodes, longest stall, CPU seconds and the calling planner method."""
    from ..planners.kernel import rrtc

    calls: list[dict[str, Any]] = []
    inner = rrtc.native_rrt_connect

    def logged(*args: Any, **kw: Any) -> Any:
        c0 = time.process_time()
        got = inner(*args, **kw)
        names = [f.name for f in traceback.extract_stack(limit=8)]
        caller = next((n for n in reversed(names) if n in ("_graft", "lookahead_graft", "branch_roots",
                                                            "constrained_extend", "_streak_connected")), names[-2])
        if caller == "_streak_connected":   # a connection step taken in C, its regrasp test applied in Python
            caller = "constrained_extend"
        if got is not None:
            calls.append({"status": got.status, "iterations": got.iterations, "tree_nodes": got.tree_nodes,
                          "longest_stall": got.longest_stall, "cpu_s": time.process_time() - c0, "caller": caller})
        return got

    rrtc.native_rrt_connect = logged
    return calls


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
    ap.add_argument("--jsonl", default=None, help="append one JSON line per query to this file")
    ap.add_argument("--compare", nargs=2, default=None, metavar=("A", "B"),
                    help="only print two --jsonl files paired per scene and trial (no planning)")
    ap.add_argument("--regrasp-calls", action="store_true",
                    help="also print every native RRT-Connect call of the regrasps and grafts")
    a = ap.parse_args(argv)
    if a.compare:
        ra, rb = ([json.loads(line) for line in open(f) if line.strip()] for f in a.compare)
        print(compare(ra, rb))
        return 0
    calls = log_regrasp_calls() if a.regrasp_calls else None
    rows = query_rows([s for s in a.scene.split(",") if s.strip()], _trials(a.trials), a.planners, seed=a.seed,
                      time_limit=a.time_limit, calls=calls)
    if a.jsonl:
        with open(a.jsonl, "a") as fh:
            for r in rows:
                fh.write(json.dumps(r) + "\n")
    for r in rows:
        for c in r.get("regrasp_calls", ()):
            print(f"  regrasp search ({c['caller']}): {c['status']}, {c['iterations']} iterations, tree nodes "
                  f"{c['tree_nodes'][0]} / {c['tree_nodes'][1]}, longest stall {c['longest_stall']}, {c['cpu_s']:.3f} s")
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
