"""Where TCBiRRT's CPU time goes: seeded benchmark queries under cProfile (CPU clock), summed per
function family (IK, edge checks, regrasps, path verification, sampling, nearest neighbour, C++
collision queries, compiled kernels).

``python -m optplan.bench.tcbirrt_profile --scene hard_bay,ssps_scene1 --trials 0,2``

The trials are the benchmark's (:class:`optplan.trials.TrialGenerator`, trial seed ``--seed``), the
planner the one ``optplan bench tcbirrt --planners`` builds from the same spec, so a profile and a
benchmark line describe the same query. Families are cumulative times and nest (the connection
regrasps run inside the constrained extensions); profiling inflates Python-level code more than
C++ calls.
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import time
from typing import Any

__all__ = ["FAMILIES", "profile_queries", "families", "format_families"]

#: (label, kind, file suffix, function name): ``kind`` "cum" (cumulative time of the function) or
#: "self" (time spent in the function itself); several rows of one label add up
FAMILIES: tuple[tuple[str, str, str, str], ...] = (
    ("whole queries (TCBiRRT._plan)", "cum", "planners/tcbirrt.py", "_plan"),
    ("set-up: end-point checks (check_endpoint)", "cum", "planners/tcbirrt.py", "check_endpoint"),
    ("set-up: the query's sampler (TCBiRRT._sampler)", "cum", "planners/tcbirrt_sampling.py", "_sampler"),
    ("result packing (ExtractPath)", "cum", "planners/tcbirrt_tree.py", "extract_path"),
    ("constrained extensions (Alg. 2, with the connection regrasps)", "cum", "planners/tcbirrt.py", "constrained_extend"),
    ("  native extension calls, self time (C)", "self", "planners/kernel/extend.py", "extend_prefix"),
    ("  native extension calls, self time (C)", "self", "planners/kernel/extend.py", "extend"),
    ("  path IK: compiled IK (ClosedChainKinematics.ik)", "cum", "constraints/closed_chain.py", "ik"),
    ("  edge checks of new constrained edges", "cum", "planners/tcbirrt_edges.py", "_edges_prefix"),
    ("  pose interpolation (interpolate_task)", "cum", "planners/task_space.py", "interpolate_task"),
    ("streaks (trapped iterations, advanced extensions and first connection steps in one C call)", "cum",
     "planners/tcbirrt_streak.py", "run"),
    ("  of which the C call, self time", "self", "planners/tcbirrt_streak.py", "run"),
    ("look-ahead grafts (frontier and trap grafts: IK, look-ahead step, regrasp)", "cum", "planners/frontier_graft.py",
     "lookahead_graft"),
    ("  IK from random seeds, loop in C (NativeExtender.ik)", "cum", "planners/kernel/extend.py", "ik"),
    ("  candidates in one C call each (seeds, IK, checks, look-ahead step), self time", "self",
     "planners/tcbirrt_lookahead.py", "next"),
    ("frontier grafts' closest pairs (nearest-neighbour queries)", "cum", "planners/frontier_graft.py", "closest_pair"),
    ("regrasps (one arm's RRTConnect, shortcuts, edge re-checks)", "cum", "planners/regrasp.py", "regrasp"),
    ("branch grafts (IK and regrasp)", "cum", "planners/tcbirrt_grafts.py", "_graft"),
    ("verify_path (second edge sampling of found paths)", "cum", "planners/tcbirrt_edges.py", "_verify_branch"),
    ("verify_path (second edge sampling of found paths)", "cum", "planners/tcbirrt_edges.py", "_verify_connection"),
    ("task-space sampling (TaskSampler.sample)", "cum", "planners/task_sampling.py", "sample"),
    ("task-space sampling, native loop (sampler and nearest node in C)", "cum", "planners/kernel/sampler.py", "sample_near"),
    ("task-space sampling, native loop (sampler and nearest node in C)", "cum", "planners/kernel/sampler.py", "sample"),
    ("  object lead path, native loop (one C call per attempt)", "cum", "planners/kernel/sampler.py", "native_lead_path"),
    ("object lead path (object_lead_path)", "cum", "planners/task_sampling.py", "object_lead_path"),
    ("nearest neighbour (Tree.nearest)", "cum", "planners/tree.py", "nearest"),
    ("native planning kernel, self time (batched checks)", "self", "planners/kernel/checker.py", "first_invalid"),
    ("native planning kernel, self time (batched checks)", "self", "planners/kernel/checker.py", "valid"),
    ("C++ collision queries, self time", "self", "planners/validity.py", "is_valid"),
    ("C++ collision queries, self time", "self", "planners/validity.py", "is_valid_free"),
    ("C++ collision queries, self time", "self", "planners/validity.py", "is_valid_object_fixed"),
    ("C++ collision queries, self time", "self", "planners/validity.py", "_collides"),
    ("C++ collision queries, self time", "self", "planners/validity.py", "first_invalid"),
    ("compiled kernels, self time (IK blocks, sweep profiles)", "self", "optplan/codegen.py", "__call__"),
)


def profile_queries(scenes: list[str], trials: list[int], planner: str = "tcbirrt:variant=improved", *,
                    seed: int = 0, time_limit: float = 10.0, robot_name: str = "tcbirrt_dual_arm") -> tuple[pstats.Stats, list[dict[str, Any]]]:
    """Run ``planner`` (a ``--planners`` spec) on trials ``trials`` of each scene under cProfile with the
    CPU clock. Returns the profile and one row per query (status, CPU s, iterations, nodes, IK
    iterations, collision checks)."""
    from .tcbirrt import _W, _worker_setup, expand_scenes

    if not trials:
        raise ValueError("profile_queries: expected at least one trial index")
    scenes = expand_scenes(scenes)
    _worker_setup(robot_name, scenes, [planner])
    prof = cProfile.Profile(time.process_time)
    rows = []
    for sc in scenes:
        w = _W[sc]
        for i in trials:
            t = w["gen"].generate(int(i), seed)
            c0 = time.process_time()
            prof.enable()
            try:
                res = w["planners"][planner].plan(t.q_start, t.q_goal, time_limit=time_limit, seed=t.seed, clock="cpu")
            finally:
                prof.disable()
            st = res.stats
            rows.append({"scene": sc, "trial": int(i), "status": res.status.value, "cpu_s": time.process_time() - c0,
                         "iterations": st.get("iterations"), "nodes": st.get("nodes"),
                         "ik_iterations": st.get("ik_iterations"), "collision_checks": st.get("collision_checks")})
    return pstats.Stats(prof), rows


def families(stats: pstats.Stats) -> list[tuple[str, float]]:
    """``(label, CPU seconds)`` per family of :data:`FAMILIES` (labels in first-seen order)."""
    raw: dict[Any, Any] = stats.stats   # type: ignore[attr-defined]  # pstats keeps its table here
    out: dict[str, float] = {}
    for label, kind, suffix, name in FAMILIES:
        t = 0.0
        for (path, _line, fn), (_cc, _nc, tt, ct, _callers) in raw.items():
            if fn == name and path.replace("\\", "/").endswith(suffix):
                t += ct if kind == "cum" else tt
        out[label] = out.get(label, 0.0) + t
    return list(out.items())


def format_families(rows: list[tuple[str, float]]) -> str:
    """A text table: family, CPU seconds, share of the whole queries."""
    total = rows[0][1] if rows and rows[0][1] > 0 else 1.0
    lines = [f"{'family':66s} {'CPU s':>8s} {'share':>6s}"]
    lines += [f"{label:66s} {t:8.2f} {100 * t / total:5.0f}%" for label, t in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.tcbirrt_profile",
                                 description="CPU profile of TCBiRRT benchmark queries, by function family")
    ap.add_argument("--scene", default="hard_bay", help="comma-separated scenes ('suite', '1' = ssps_scene1, ...)")
    ap.add_argument("--trials", default="0", help="comma-separated trial indices [index]")
    ap.add_argument("--planners", default="tcbirrt:variant=improved", help="one planner spec, as for 'optplan bench tcbirrt'")
    ap.add_argument("--seed", type=int, default=0, help="trial seed")
    ap.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds per query [s]")
    ap.add_argument("--out", default=None, help="write the raw profile here (pstats format)")
    ap.add_argument("--top", type=int, default=0, help="also print the N functions of largest self time")
    a = ap.parse_args(argv)
    trials = [int(x) for x in a.trials.split(",") if x.strip()]
    stats, rows = profile_queries(a.scene.split(","), trials, a.planners, seed=a.seed, time_limit=a.time_limit)
    for r in rows:
        print(f"{r['scene']} trial {r['trial']}: {r['status']}, {r['cpu_s']:.2f} s CPU (profiled), "
              f"{r['iterations']} iterations, {r['nodes']} nodes, {r['ik_iterations']} IK iterations, "
              f"{r['collision_checks']} collision checks")
    print(format_families(families(stats)))
    if a.out:
        stats.dump_stats(a.out)
    if a.top:
        stats.sort_stats("tottime").print_stats(a.top)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
