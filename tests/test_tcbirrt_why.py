"""The TCBiRRT diagnosis bench: its per-scene figures from known rows, and one real query's counters."""
from __future__ import annotations

from optplan.bench.tcbirrt_why import _trials, compare, log_regrasp_calls, query_rows, scene_summary


def _row(its, status="exact", cpu=1.0, regrasp_s=0.25, n_regrasp=2):
    return {"status": status, "cpu_s": cpu, "iterations": its, "regrasp_s": regrasp_s, "n_regrasp": n_regrasp,
            "graft_after": 1500, "frontier_interval": 50, "frontier_on": True, "graft_attempts": 3, "grafts": 1,
            "regrasp_attempts": 2, "regrasp_failures": 0}


def test_scene_summary_counts_frontier_graft_endings():
    rows = [_row(2950), _row(3001), _row(300, n_regrasp=0), _row(9000, status="timeout", n_regrasp=0)]
    s = scene_summary(rows)
    assert (s["n"], s["success"], s["with_regrasp"]) == (4, 3, 2)
    assert (s["past_graft_after"], s["at_frontier_graft"]) == (3, 1)   # 2950 = 1500 + 29 x 50; 3001 is not; 9000 failed
    assert abs(s["regrasp_share"] - 0.25) < 1e-12
    assert _trials("0-2,5") == [0, 1, 2, 5]


def test_one_query_counters(tcb):
    rows = query_rows(["hard_corridor"], [0], time_limit=10.0)
    r = rows[0]
    assert r["status"] == "exact" and r["iterations"] >= 1 and 0 < r["cpu_s"] < 10.0
    assert r["graft_after"] == 1500 and r["frontier_on"]


def _q(scene, trial, its, cpu, length, status="exact", nodes=10, ik=100):
    return {"scene": scene, "trial": trial, "status": status, "cpu_s": cpu, "iterations": its, "nodes": nodes,
            "ik_iterations": ik, "joint_length": length}


def test_compare_pairs_rows_by_scene_and_trial():
    a = [_q("s", 0, 100, 1.0, 10.0), _q("s", 1, 200, 2.0, 20.0), _q("s", 2, 300, 3.0, None, status="timeout")]
    b = [_q("s", 1, 200, 1.0, 30.0), _q("s", 0, 100, 0.5, 10.0), _q("s", 2, 150, 1.5, 5.0, nodes=4)]   # other order
    row = compare(a, b).splitlines()[2].split(" | ")
    assert row[1] == "2/3, 2.000, 200" and row[2] == "3/3, 1.000, 150"
    assert row[3] == f"{(6.0 / 600) / (3.0 / 450):.2f}×"   # total CPU / total iterations, a over b
    assert row[4] == "2/3" and row[5] == "1.250"   # trial 2 ran another search; lengths b / a of the two solved: 1.0, 1.5
    assert row[6].startswith("3.00 → 1.50")


def test_regrasp_calls_are_logged_per_query(tcb):
    from optplan.planners.kernel import rrtc

    inner = rrtc.native_rrt_connect
    try:
        calls = log_regrasp_calls()
        rows = query_rows(["hard_bay"], [2], calls=calls)
    finally:
        rrtc.native_rrt_connect = inner
    got = rows[0]["regrasp_calls"]
    assert rows[0]["regrasp_attempts"] >= 1 and got   # hard_bay trial 2 regrasps once (two arms)
    for c in got:
        assert c["status"] == "found" and sum(c["tree_nodes"]) >= 0 and c["caller"] in ("constrained_extend", "_graft")
