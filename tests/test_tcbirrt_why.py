"""The TCBiRRT diagnosis bench: its per-scene figures from known rows, and one real query's counters."""
from __future__ import annotations

from optplan.bench.tcbirrt_why import _trials, query_rows, scene_summary


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
